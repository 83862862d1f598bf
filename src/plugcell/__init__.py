"""plugcell — plug-and-produce robot work-cells made accurate.

Pure-math packages (``kinematics``, ``calibration``, ``compensation``,
``metrology``) never import the framework (``framework``, ``services``, ``ui``).
"""

__version__ = "0.1.0"
