"""plugcell.sim.twin."""
