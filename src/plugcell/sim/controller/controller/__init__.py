"""The old program path of the simulated controller, kept so that
``python -m plugcell.sim.controller.controller`` (docs and scripts of before issue 33)
still runs it: the program is :mod:`plugcell.apps.commands.sim_controller`
(``python -m plugcell.sim.controller``), the controller
:mod:`plugcell.sim.controller.line_controller`."""
