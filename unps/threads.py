"""How many threads one fit should use: the CPUs it is given, shared with the sweep's other jobs.

torch starts as many threads as the machine has cores. Two fits that each do so on two cores
fight over them (each thread waits for the other process's at every parallel region): measured
here, a step took 10× longer, not 2×. A fit therefore takes its share: the CPUs this process may
run on (its affinity mask, which SLURM and ``taskset`` set), divided by the number of fits the
launcher runs at once (``hydra.launcher.n_jobs`` of the joblib launcher).
"""

from __future__ import annotations

import os

import torch

from unps.errors import InputError


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:     # macOS, Windows
        return os.cpu_count() or 1


def parallel_jobs(launcher: dict | None, cpus: int) -> int:
    """Fits a Hydra launcher runs at once: joblib's ``n_jobs`` (−1 = one per CPU), else 1."""
    n_jobs = (launcher or {}).get("n_jobs")
    if n_jobs is None:
        return 1
    n_jobs = int(n_jobs)
    return cpus if n_jobs < 0 else max(n_jobs, 1)


def share(cpus: int, jobs: int) -> int:
    """Threads per fit: the CPUs split evenly between the jobs, at least one.

    Example:
        >>> share(2, 2), share(16, 3), share(2, 4)
        (1, 5, 1)
    """
    return max(cpus // max(jobs, 1), 1)


def set_fit_threads(requested: int | None, launcher: dict | None) -> tuple[int, str]:
    """Set torch's intra-op threads for this fit; return them and where the number came from.

    ``requested`` (the ``threads=`` option) wins; then an ``OMP_NUM_THREADS`` the user set;
    otherwise :func:`share` of :func:`available_cpus` between the launcher's parallel jobs.
    """
    if requested is not None:
        if int(requested) < 1:
            raise InputError(f"threads must be a whole number >= 1 (or null for automatic), got {requested}")
        threads, source = int(requested), "threads="
    elif os.environ.get("OMP_NUM_THREADS", "").isdigit():
        threads, source = max(int(os.environ["OMP_NUM_THREADS"]), 1), "OMP_NUM_THREADS"
    else:
        cpus = available_cpus()
        jobs = parallel_jobs(launcher, cpus)
        threads = share(cpus, jobs)
        source = f"{cpus} CPUs" + (f" shared by {jobs} parallel fits" if jobs > 1 else "")
    torch.set_num_threads(threads)
    return threads, source
