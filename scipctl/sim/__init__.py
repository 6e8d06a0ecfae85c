"""Synthetic downlinks with exact truth (see docs/simulator.md).

* :mod:`.rover` -- the simulated rover (``default_rover_config``), image rescaling for tests.
* :mod:`.scene` -- terrain, rocks, pebbles, procedural albedo, Open3D ray casting.
* :mod:`.render` -- rendering through exact JPL models, radiometry (``render_radiance``, ``expose``).
* :mod:`.errors` -- calibration, odometry, vibration, gain errors (``ErrorSettings``).
* :mod:`.scenarios` -- the ``paper`` and ``traverse`` scenarios (``build_run`` -> ``SimRun`` with a
  :class:`scipctl.model.Downlink`).

Nothing here touches files; ``scipctl synth`` (scipctl/commands/synth.py) writes the downlinks.
"""
