"""Recordings: the `idm-recording/1` format read and checked (:mod:`.recording`, its tables and
errors), and recordings written by simulation with a sensor's noise (:mod:`.synthetic`,
:mod:`.sensor_noise`). Uses the core layer only."""
