"""plugcell.kinematics."""
