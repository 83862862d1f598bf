"""The laser tracker service: Table 7-3 of the thesis, one tracker for many robots.

* :mod:`.service` — ``TrackerService``: its catalogue, its requesters, the measurements;
* :mod:`.driver` — the seam between the service and a tracker (real or simulated);
* :mod:`.frames` — the frames of one requester: BASE, PROBE and its angle convention;
* :mod:`.routing` — who a process is for, and where its output data goes (``to=``).
"""
