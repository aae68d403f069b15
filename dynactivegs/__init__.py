"""dynactivegs: active 3D Gaussian Splatting reconstruction in dynamic scenes.

The core package is pure: it never imports ``mcap``, ``rerun``, ``recorder`` or
``replay``. Sub-packages: ``sim`` (the embedded simulator), ``splat`` (Gaussian
model and rasterizers), one package per pipeline stage, and ``eval``.
"""

__version__ = "0.1.0"
