"""sonarmap's command line (typer): the only layer that turns errors into exit codes."""

import os

# sonarmap runs its own threads (the mapper's row bands, refinement's two starts); BLAS
# threads on top of them oversubscribe the cores: one BLAS thread each unless the user says.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
