"""Synthetic downlinks with exact truth (see docs/simulator.md).

* :mod:`.rover` -- the simulated rover (``default_rover_config``), image rescaling for tests.
* :mod:`.scene` -- the assembled scene (terrain, rocks, pebbles) and its Open3D ray casting, built from
  :mod:`.terrain` (height field, graded grid), :mod:`.mesh` (hull meshes), :mod:`.rocks`,
  :mod:`.appearance` (procedural albedo) and :mod:`.noise`.
* :mod:`.render` -- rendering through exact JPL models, radiometry (``render_radiance``, ``expose``).
* :mod:`.errors` -- calibration, odometry, vibration, gain errors (``ErrorSettings``).
* :mod:`.scenarios` -- the ``paper`` and ``traverse`` scenarios (``plan_run`` -> ``RunPlan``).
* :mod:`.build` -- a run from its plan (``build_run`` -> ``SimRun`` with a :class:`scipctl.model.Downlink`),
  with :mod:`.placement`, :mod:`.products`, :mod:`.targets` and :mod:`.marks`.

Nothing here touches files; ``scipctl synth`` (scipctl/commands/synth.py) writes the downlinks.
"""
