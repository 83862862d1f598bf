"""plugcell.controller — the simulated robot controller.

:mod:`plugcell.controller.language` is the PDL-style robot language (parser and
interpreter) that the simulated controller runs; example programs live in
``plugcell/controller/programs``.  The controller process, its TCP protocol and
the robot service are built on top of the language runtime.
"""
