"""Validation campaigns: the handoff methods, the chain and the pre-uplink prediction over many downlinks
(files, or synthetic scenes rendered on the workers), on a Dask cluster, with results that survive (docs/campaign.md).

The layer above ``sim`` and ``pipeline`` and below ``commands``: it orchestrates them and never prints.

One concept per module: ``options`` (what is run on each downlink, :class:`CampaignOptions`), ``jobs`` (the
downlinks: files, directories, globs, or synthetic (scenario, run, seed, family); :class:`DownlinkJob`),
``task`` (what a worker does with one job: :func:`run_job` -> :class:`DownlinkResult`), ``results`` (that result and
its JSONL records file), ``store`` (the output folder: records written atomically, the manifest, what is already
done), ``cluster`` (a local Dask cluster sized to the machine, or an existing scheduler), ``run`` (the whole
campaign: :func:`run_campaign`), ``summary`` (the aggregate: Table 1 per family, chains, predictions,
GO/NO-GO, reliability, the slowest downlinks).
"""
