"""The campaign folder's writes (scipctl.campaign.store): a records file or manifest that cannot be written is bad
input naming that file (exit 2), not an internal error naming the temporary file beside it, and leaves nothing."""

import pytest

from scipctl.campaign.jobs import DownlinkJob
from scipctl.campaign.options import CampaignOptions, job_key
from scipctl.campaign.results import DownlinkResult
from scipctl.campaign.store import FORMAT, CampaignStore
from scipctl.errors import InputError

OPTIONS = CampaignOptions(methods=("pure-kinematic",), pairs=(("pure-kinematic", "near"),))


def test_a_records_file_or_manifest_that_cannot_be_written_is_named(tmp_path):
    store = CampaignStore(tmp_path / "out")
    store.make()
    job = DownlinkJob("a", "fam", "0" * 64)
    res = DownlinkResult(job, job_key(job.input_sha256, OPTIONS.key()))
    store.records_path(job).mkdir()  # a folder where the records file goes (os.replace: IsADirectoryError)
    with pytest.raises(InputError) as e:
        store.write(res)
    assert e.value.product == str(store.records_path(job)) and e.value.field == "-o/--out"
    store.manifest_path.mkdir()
    with pytest.raises(InputError) as e:
        store.save_manifest({"format": FORMAT, "downlinks": {}})
    assert e.value.product == str(store.manifest_path)
    # nothing left behind: no temporary file beside either
    assert sorted(p.name for p in store.records_dir.iterdir()) == [store.records_path(job).name]
    assert sorted(p.name for p in store.out.iterdir()) == ["manifest.json", "records"]
