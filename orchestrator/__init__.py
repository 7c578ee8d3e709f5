"""Orchestrator: the fmpy master, scenarios, results and the ``fullpose`` CLI."""

import os

# numpy asks Linux for transparent huge pages for each array of 4 MiB or more
# (madvise(MADV_HUGEPAGE)); where the kernel has to compact memory to find them (THP defrag
# "madvise", the default) a run's first touch of its recording stalls: the 100 s scenario's
# 70 MB took 0.1-0.65 s of kernel time instead of 27-38 ms with 4 KiB pages, and
# `fullpose run hover_varying_orientation` 2.3-2.6 s instead of 1.7-1.9 s (a 2-vCPU VM,
# Linux 6.18; docs/orchestrator.md).  numpy reads the variable when it is first imported:
# so in the fullpose command, which imports this package first, in any program that does,
# and in the processes they start (figure, sweep and Dask workers).  A value already set wins.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
