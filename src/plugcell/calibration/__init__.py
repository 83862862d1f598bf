"""plugcell.calibration."""
