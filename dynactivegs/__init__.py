"""dynactivegs: active 3D Gaussian Splatting reconstruction in dynamic scenes.

The core package is pure: it never imports ``mcap``, ``rerun``, ``recorder`` or
``replay``. Sub-packages: ``sim`` (the embedded simulator), ``splat`` (Gaussian
model and rasterizers), one package per pipeline stage, and ``eval``.
"""

import os

# Threads of PyTorch's OpenMP runtime sleep instead of spinning while they wait. The stages run
# many small torch ops between numba kernels and the simulator; with spinning waiters a busy
# second core made perception steps 10x slower (1.9 s vs 0.15 s per frame on 2 cores). This only
# takes effect if set before torch is first imported, and a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

__version__ = "0.1.0"
