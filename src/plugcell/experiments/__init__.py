"""plugcell.experiments — the thesis's experiments that need the digital twin.

Not pure math: these modules drive :mod:`plugcell.twin` (the simulated robot and
laser tracker) through the same device protocols the services implement.  The
pure-math packages (kinematics, calibration, compensation, metrology) never import
this package.

* :mod:`.reproduce_8_3` — thesis 8.3, two-stage error compensation (``plugcell
  reproduce 8.3``); :mod:`.pages_8_3` writes its table, figures and page.
* :mod:`.twin_devices` — the twin and the tracker model behind
  :mod:`plugcell.compensation.protocols`.
"""
