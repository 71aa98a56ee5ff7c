"""Imported by the fork server of ``batch``'s local workers only (decision 2008): the server
leaves with ``os._exit`` when the batch ends, without tearing its modules down (numba, scipy,
pyarrow, Dask: about 0.3 s that the batch's process would wait for). Its forked workers never
run exit handlers (multiprocessing ends them with ``os._exit``), so this handler is the
server's alone."""

import atexit
import os

atexit.register(os._exit, 0)
