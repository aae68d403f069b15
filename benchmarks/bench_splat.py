"""Forward+backward time of the splat rasterizers: torch reference vs the numba CPU backend.

    python benchmarks/bench_splat.py            # full table (a few minutes on 2 cores)
    python benchmarks/bench_splat.py --quick    # 5k / 20k only

For each image size (160x92, 320x184) and Gaussian count (5k, 20k, 50k, all in view) it
times one render plus the backward pass of an L1 + depth loss, for the reference
(``backend="reference"``) and the fast backend (``backend="cpu"``), in one run, and prints
the median wall times and their ratio, and the fast backend's CPU time per pass summed over
its threads (``cpu CPU-ms``: on an otherwise idle machine with k cores the wall time
approaches this divided by k; on a shared machine the wall time is what other processes
leave). The reference is timed with fewer repeats where it is
slow (the ``ref reps`` column says how many). Then, each in a fresh subprocess so that
nothing else is counted, the peak resident memory of one forward+backward of 50k Gaussians
at 320x184 (the process's VmHWM: the whole process, Python and torch included). Where a
CUDA device and gsplat are present, the gsplat backend is timed too.

The scene is a depth-map-like cloud: Gaussians at random pixels and depths 1-5 m, screen
size ~0.8 px x sqrt(pixels per Gaussian), opacity 0.3-0.95, random rotations and colours.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import resource
import subprocess
import sys
import time

# torch's OpenMP workers busy-wait ("active" policy) after every op, which on a 2-core machine
# steals the cores from the numba threads that run next (and from the reference's own next op).
# The benchmark asks for passive waiting unless the caller set a policy; the header prints it.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from dynactivegs.splat import Gaussians, render  # noqa: E402
from dynactivegs.splat.losses import depth_l1, l1  # noqa: E402


def scene(n: int, width: int, height: int, seed: int = 0) -> tuple[Gaussians, np.ndarray, np.ndarray, torch.Tensor]:
    """(gaussians, K, T_world_cam, target rgb) with all n Gaussians in view of a 90 deg camera."""
    gen = torch.Generator().manual_seed(seed)
    f = 0.5 * width / math.tan(math.radians(45.0))
    K = np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    u = torch.rand(n, generator=gen) * width
    v = torch.rand(n, generator=gen) * height
    z = 1.0 + 4.0 * torch.rand(n, generator=gen)
    sigma_px = 0.8 * math.sqrt(width * height / n) * (0.5 + torch.rand(n, 3, generator=gen))
    means = torch.stack([(u - width / 2) / f * z, (v - height / 2) / f * z, z], dim=-1)
    g = Gaussians.from_params(means, sigma_px * z[:, None] / f, torch.randn(n, 4, generator=gen),
                              0.3 + 0.65 * torch.rand(n, generator=gen), torch.rand(n, 3, generator=gen))
    target = torch.rand(height, width, 3, generator=gen)
    return g, K, T, target


def fwd_bwd(g: Gaussians, K, T, width: int, height: int, target: torch.Tensor, backend: str) -> None:
    out = render(g, K, T, width, height, backend=backend)
    loss = l1(out.rgb, target) + 0.1 * depth_l1(out.depth, torch.full_like(out.depth, 3.0))
    loss.backward()


def time_it(g, K, T, width, height, target, backend: str, reps: int) -> tuple[float, float]:
    """Median wall seconds of ``reps`` forward+backward passes after one warm-up, and the mean
    CPU seconds per pass summed over all threads (``time.process_time``)."""
    g = g.to(device="cuda") if backend == "cuda" else g
    g.requires_grad_()
    target = target.to(g.device)
    fwd_bwd(g, K, T, width, height, target, backend)
    times = []
    cpu0 = time.process_time()
    for _ in range(reps):
        for t in g.tensors():
            t.grad = None
        if backend == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fwd_bwd(g, K, T, width, height, target, backend)
        if backend == "cuda":
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), (time.process_time() - cpu0) / reps


def peak_memory_subprocess(backend: str, n: int, width: int, height: int) -> float:
    """Peak RSS in MiB of a fresh process doing one warm-up and one timed forward+backward."""
    cmd = [sys.executable, __file__, "--memory-probe", backend, str(n), str(width), str(height)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return float(out.strip().splitlines()[-1])


def peak_rss_mib() -> float:
    """This process's peak resident set: VmHWM (reset at exec, unlike ru_maxrss, which a child
    inherits from the parent it was forked from), else ru_maxrss."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0   # KiB on Linux


def memory_probe(backend: str, n: int, width: int, height: int) -> None:
    g, K, T, target = scene(n, width, height)
    g.requires_grad_()
    fwd_bwd(g, K, T, width, height, target, backend)
    print(peak_rss_mib())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only 5k and 20k Gaussians")
    parser.add_argument("--memory-probe", nargs=4, metavar=("BACKEND", "N", "W", "H"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.memory_probe:
        backend, n, w, h = args.memory_probe
        memory_probe(backend, int(n), int(w), int(h))
        return

    import numba

    from dynactivegs.splat.render import gsplat_available

    with_cuda = gsplat_available()
    counts = (5_000, 20_000) if args.quick else (5_000, 20_000, 50_000)
    sizes = ((160, 92), (320, 184))
    print(f"# splat forward+backward, {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"torch {torch.__version__} ({torch.get_num_threads()} threads), numba {numba.__version__}, "
          f"OMP_WAIT_POLICY={os.environ['OMP_WAIT_POLICY']}; load average before: {os.getloadavg()[0]:.2f}")
    header = "| image | Gaussians | reference ms | ref reps | cpu ms | cpu reps | speed-up | cpu CPU-ms |"
    if with_cuda:
        header += " gsplat ms |"
    print(header)
    print("|" + "|".join("---" for _ in header.split("|")[1:-1]) + "|")
    for width, height in sizes:
        for n in counts:
            g, K, T, target = scene(n, width, height)
            fast_reps = 10
            ref_reps = 3 if n * width * height <= 20_000 * 160 * 92 else 1
            t_fast, cpu_fast = time_it(g, K, T, width, height, target, "cpu", fast_reps)
            t_ref, _ = time_it(g, K, T, width, height, target, "reference", ref_reps)
            row = (f"| {width}x{height} | {n:,} | {t_ref * 1e3:.0f} | {ref_reps} | {t_fast * 1e3:.1f} | {fast_reps} "
                   f"| {t_ref / t_fast:.1f}x | {cpu_fast * 1e3:.1f} |")
            if with_cuda:
                row += f" {time_it(g, K, T, width, height, target, 'cuda', 20)[0] * 1e3:.2f} |"
            print(row, flush=True)
    print(f"# numba threading layer: {numba.threading_layer()}, {numba.get_num_threads()} threads; "
          f"load average after: {os.getloadavg()[0]:.2f}")
    if not with_cuda:
        print("# no CUDA device with gsplat here: the gsplat column is not measured")
    n, (w, h) = 50_000, (320, 184)
    for backend in ("cpu", "reference"):
        mib = peak_memory_subprocess(backend, n, w, h)
        print(f"# peak RSS, one forward+backward, {n:,} Gaussians at {w}x{h}, backend={backend}: "
              f"{mib:.0f} MiB (whole process)")


if __name__ == "__main__":
    main()
