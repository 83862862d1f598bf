"""``plugcell demo``: chapter 8 of the thesis end to end over services.

* :mod:`.services` — starts the cell's services as processes, runs the robot programs
  and gathers the figures;
* :mod:`.processes` — follows the cell's processes for the demo's log.
"""
