"""``thermotilt campaign``: the paper's calibration (section 3.2), the tilt
table at each position, each through a full -10 -> 45 -> -10 degC staircase,
in the twin or on real boards; its folder (``folder``), its plan
(``plan``) and the runners: here or in worker processes (``local``), on a
Dask cluster (``dask``), on real boards (``rig``)."""
