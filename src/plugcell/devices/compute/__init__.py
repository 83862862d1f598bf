"""The compute service: the Matlab service of thesis 7.3 (Table 7-2), without Matlab.

* :mod:`.service` — ``ComputeService``: its catalogue and dispatch;
* :mod:`.workspace` — a workspace of named values, one per requester;
* :mod:`.expr` — the expression language of ``Evaluate``;
* :mod:`.functions` — the functions ``Evaluate`` may call (frames, fits, calibration).
"""
