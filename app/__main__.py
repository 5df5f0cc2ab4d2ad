import os

# One BLAS thread per lab process, set before numpy loads OpenBLAS: the lab's matrices are small
# (4 × 4 to 200 × 200), and OpenBLAS's helper threads spin while they wait, which on a lab server
# doubled the CPU of an analysis (lqg_vs_pid's Analysis tab: 208 ms of its own thread, 432 ms in all)
# and took it from the tabs' streaming.  A value already set in the environment is kept.
for variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(variable, "1")

from app.cli import main  # after the thread settings

raise SystemExit(main())
