"""The test process runs BLAS on one thread, as the CLI does (decision 2004)."""

from millsense.core.blas import default_to_one_thread, limit_blas_threads

default_to_one_thread()
limit_blas_threads(1)
