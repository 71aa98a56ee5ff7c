"""Fast, standard HDF5 chunk I/O for 1-D numeric datasets: shuffle + deflate done in threads.

Every dataset written here declares the ordinary HDF5 filter pipeline *shuffle, deflate* (what
``h5py.create_dataset(..., compression="gzip", shuffle=True)`` declares), so h5py, MATLAB
``h5read`` and any HDF5 reader decode it with the stock filters. What differs is who runs the
filters: instead of HDF5 compressing chunk by chunk under h5py's global lock, chunks are
shuffled with numpy and deflated with :mod:`zlib` in a thread pool (zlib releases the GIL),
then stored with ``write_direct_chunk``; reading does the reverse, fetching chunks by their
file offsets from HDF5's chunk index (or ``read_direct_chunk``).

Notes
-----
HDF5's shuffle filter stores, for a chunk of :math:`n` elements of :math:`s` bytes, byte
:math:`j` of element :math:`i` at position :math:`j n + i`; with numpy that is
``chunk.view(uint8).reshape(n, s).T``. The deflate filter stores a zlib stream (RFC 1950) of
the whole, always full-size chunk (edge chunks are padded with the fill value 0). Our stream
emits byte planes whose sampled entropy exceeds 7.8 bit (the noisy low mantissa bytes) as
stored blocks and deflates the others with strategy ``Z_RLE``; both choices are measured in
``docs/decisions/0020-recording-files-compression-and-chunking-chosen-by.md``.
Any inflate implementation reads the result.

Datasets not written this way (other filters, a skipped filter, an unallocated chunk) are read
through h5py's normal path, so the reader accepts any valid file.
"""

from __future__ import annotations

import os
import zlib
from concurrent.futures import Future, ThreadPoolExecutor

import h5py
import numpy as np

__all__ = [
    "CHUNK_SAMPLES",
    "DEFLATE_LEVEL",
    "IO_THREADS_ENV",
    "ChunkAppender",
    "create_chunked",
    "decode_chunk",
    "encode_chunk",
    "io_threads",
    "read_array",
    "write_array",
]

#: Samples per HDF5 chunk (65536 float64 = 512 KiB); chosen by measurement,
#: see docs/decisions/0020-recording-files-compression-and-chunking-chosen-by.md.
CHUNK_SAMPLES = 65536
#: zlib level; with the Z_RLE strategy the level barely changes size or speed.
DEFLATE_LEVEL = 1
_STRATEGY = zlib.Z_RLE
#: zlib memLevel 8 (its default); 9 makes the stream 3x slower to inflate (measured).
_MEM_LEVEL = 8
#: zlib header for deflate with a 32 KiB window (0x7801 is a multiple of 31, RFC 1950).
_ZLIB_HEADER = b"\x78\x01"
#: Bytes sampled per plane to estimate its entropy, and the entropy above which it is stored.
_ENTROPY_SAMPLE = 4096
_RANDOM_BITS = 7.8

_POOL: ThreadPoolExecutor | None = None
_POOL_PID = -1


#: Environment variable: threads of the chunk codec (default: the CPU count, at most 8).
#: ``millsense batch`` sets it to 1 in its workers: the workers are the parallelism.
IO_THREADS_ENV = "MILLSENSE_IO_THREADS"


def io_threads() -> int:
    """Threads of the chunk codec: ``$MILLSENSE_IO_THREADS`` (≥ 1), else the CPU count (≤ 8)."""
    text = os.environ.get(IO_THREADS_ENV, "")
    if text.strip().isdigit() and int(text) >= 1:
        return int(text)
    return max(1, min(8, os.cpu_count() or 1))


def _pool() -> ThreadPoolExecutor:
    """Process-wide worker pool (re-created after fork)."""
    global _POOL, _POOL_PID
    if _POOL is None or _POOL_PID != os.getpid():
        workers = io_threads()
        _POOL = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="millsense-h5")
        _POOL_PID = os.getpid()
    return _POOL


def encode_chunk(values: np.ndarray, chunk_len: int, level: int = DEFLATE_LEVEL) -> bytes:
    """Shuffle and deflate ``values`` (at most ``chunk_len`` elements) as one HDF5 chunk.

    Parameters
    ----------
    values : numpy.ndarray
        1-D, native byte order, ``len(values) <= chunk_len``; padded with zeros to a full chunk.
    chunk_len : int
        Chunk length of the dataset, elements.
    level : int
        zlib compression level.

    Returns
    -------
    bytes
        The stored chunk, decodable by HDF5's shuffle + deflate filters.
    """
    # a strided view (a stream field given as t[::2]) has no byte planes to view
    values = np.ascontiguousarray(values)
    m = values.shape[0]
    if m < chunk_len:
        full = np.zeros(chunk_len, dtype=values.dtype)
        full[:m] = values
        values = full
    size = values.dtype.itemsize
    planes = np.ascontiguousarray(values.view(np.uint8).reshape(chunk_len, size).T)
    stored = [_looks_random(planes[j]) for j in range(size)]
    # One zlib stream (RFC 1950): header, raw deflate blocks, Adler-32 of the whole chunk.
    # Runs of byte planes with the same decision are deflated by separate raw compressors
    # and joined at byte boundaries (Z_SYNC_FLUSH ends on one; only the last is final).
    parts = [_ZLIB_HEADER]
    j = 0
    while j < size:
        k = j + 1
        while k < size and stored[k] == stored[j]:
            k += 1
        comp = zlib.compressobj(
            0 if stored[j] else level, zlib.DEFLATED, -15, _MEM_LEVEL, _STRATEGY
        )
        parts.append(comp.compress(planes[j:k].data))
        parts.append(comp.flush(zlib.Z_FINISH if k == size else zlib.Z_SYNC_FLUSH))
        j = k
    parts.append(zlib.adler32(planes.data).to_bytes(4, "big"))
    return b"".join(parts)


def _looks_random(plane: np.ndarray) -> bool:
    """True if a byte plane is incompressible (byte entropy of a sample > 7.8 bit).

    Such planes (the low mantissa bytes of noisy floats) are stored, not searched for
    matches: the deflate stream stays standard and both directions get faster.
    """
    step = max(1, plane.shape[0] // _ENTROPY_SAMPLE)
    counts = np.bincount(plane[::step], minlength=256)
    p = counts[counts > 0] / counts.sum()
    return bool(-(p * np.log2(p)).sum() > _RANDOM_BITS)


def decode_chunk(raw: bytes | memoryview, out: np.ndarray, chunk_len: int) -> None:
    """Inflate and unshuffle one stored chunk into ``out`` (the first ``len(out)`` elements).

    Raises
    ------
    ValueError
        If the chunk does not inflate to ``chunk_len`` elements (corrupt data).
    """
    size = out.dtype.itemsize
    plain = zlib.decompress(raw, 15, chunk_len * size)
    if len(plain) != chunk_len * size:
        raise ValueError(f"chunk inflates to {len(plain)} bytes, expected {chunk_len * size}")
    m = out.shape[0]
    planes = np.frombuffer(plain, dtype=np.uint8).reshape(size, chunk_len)
    dest = out.view(np.uint8).reshape(m, size)
    for j in range(size):  # one strided copy per byte plane: 2x faster than one .T copy
        dest[:, j] = planes[j, :m]


def create_chunked(
    group: h5py.Group,
    name: str,
    dtype: np.dtype,
    chunk_len: int,
    shape: int = 0,
    resizable: bool = True,
) -> h5py.Dataset:
    """Create a 1-D dataset declaring the shuffle + deflate pipeline.

    ``name`` may contain ``/``: intermediate groups are created.
    """
    return group.create_dataset(
        name,
        shape=(shape,),
        maxshape=(None,) if resizable else (shape,),
        dtype=dtype,
        chunks=(chunk_len,),
        compression="gzip",
        compression_opts=DEFLATE_LEVEL,
        shuffle=True,
        fillvalue=0,
    )


def _chunk_len_for(n: int) -> int:
    return max(1, min(CHUNK_SAMPLES, n))


def write_array(
    group: h5py.Group, name: str, values: np.ndarray, chunk_len: int | None = None
) -> h5py.Dataset:
    """Write a whole 1-D array as a compressed chunked dataset (chunks encoded in parallel)."""
    n = values.shape[0]
    clen = chunk_len or _chunk_len_for(n)
    ds = create_chunked(group, name, values.dtype, clen, shape=n, resizable=n == 0)
    pool = _pool()
    futures = [pool.submit(encode_chunk, values[s : s + clen], clen) for s in range(0, n, clen)]
    for k, fut in enumerate(futures):
        ds.id.write_direct_chunk((k * clen,), fut.result())
    return ds


class ChunkAppender:
    """Append samples to a resizable dataset; full chunks are encoded in the worker pool.

    Parameters
    ----------
    ds : h5py.Dataset
        A dataset made by :func:`create_chunked` (resizable, length 0).
    """

    def __init__(self, ds: h5py.Dataset) -> None:
        self.ds = ds
        self.chunk_len = int(ds.chunks[0])
        self._buffer: list[np.ndarray] = []
        self._buffered = 0
        self._chunks_done = 0  # chunks written to the file
        self._futures: list[Future[bytes]] = []
        self.n = 0  # samples appended

    def append(self, values: np.ndarray) -> None:
        """Queue ``values``; every completed chunk is handed to the pool."""
        if values.shape[0] == 0:
            return
        self._buffer.append(values)
        self._buffered += values.shape[0]
        self.n += values.shape[0]
        if self._buffered >= self.chunk_len:
            data = np.concatenate(self._buffer) if len(self._buffer) > 1 else self._buffer[0]
            n_full = data.shape[0] // self.chunk_len * self.chunk_len
            pool = _pool()
            for s in range(0, n_full, self.chunk_len):
                self._futures.append(
                    pool.submit(encode_chunk, data[s : s + self.chunk_len], self.chunk_len)
                )
            rest = data[n_full:]
            self._buffer = [rest] if rest.shape[0] else []
            self._buffered = rest.shape[0]
        self.drain(wait=len(self._futures) > 8)

    def drain(self, wait: bool = False) -> None:
        """Write encoded chunks to the file in order (block on them if ``wait``)."""
        while self._futures and (wait or self._futures[0].done()):
            raw = self._futures.pop(0).result()
            k = self._chunks_done
            self.ds.resize(((k + 1) * self.chunk_len,))
            self.ds.id.write_direct_chunk((k * self.chunk_len,), raw)
            self._chunks_done += 1

    def finish(self) -> None:
        """Encode the partial last chunk, write everything, set the exact length."""
        self.drain(wait=True)
        if self._buffered:
            data = np.concatenate(self._buffer)
            k = self._chunks_done
            self.ds.resize((self.n,))
            self.ds.id.write_direct_chunk((k * self.chunk_len,), encode_chunk(data, self.chunk_len))
            self._chunks_done += 1
            self._buffer, self._buffered = [], 0
        elif self.ds.shape[0] != self.n:
            self.ds.resize((self.n,))


def _is_fast_path(ds: h5py.Dataset) -> bool:
    """True if ``ds`` is 1-D, chunked, native numeric, with exactly shuffle then deflate."""
    if ds.ndim != 1 or ds.chunks is None or ds.dtype.kind not in "iuf":
        return False
    if not ds.dtype.isnative:
        return False
    plist = ds.id.get_create_plist()
    codes = [plist.get_filter(i)[0] for i in range(plist.get_nfilters())]
    return codes == [h5py.h5z.FILTER_SHUFFLE, h5py.h5z.FILTER_DEFLATE]


def read_array(
    ds: h5py.Dataset,
    pending: list[Future[None]] | None = None,
    mapped: memoryview | None = None,
) -> np.ndarray:
    """Read a whole 1-D dataset; chunks of the standard pipeline are decoded in parallel.

    Parameters
    ----------
    ds : h5py.Dataset
        Dataset to read.
    pending : list of Future, optional
        If given, decoding futures are appended here and the caller must wait on them before
        using the array (lets several datasets decode concurrently); otherwise this waits.
    mapped : memoryview, optional
        The whole file, memory-mapped read-only. Chunks are then located with HDF5's chunk
        index (``chunk_iter``) and inflated straight from the mapping in the workers, without
        a copy through HDF5; otherwise they are fetched with ``read_direct_chunk``.

    Returns
    -------
    numpy.ndarray
        The samples (possibly still being filled if ``pending`` was given).
    """
    n = int(ds.shape[0]) if ds.ndim == 1 else -1
    if n <= 0 or not _is_fast_path(ds):
        return np.asarray(ds[()])
    out = np.empty(n, dtype=ds.dtype)
    clen = int(ds.chunks[0])
    futures: list[Future[None]] = [] if pending is None else pending
    first = len(futures)
    pool = _pool()
    done: set[int] = set()
    if mapped is not None and hasattr(ds.id, "chunk_iter"):
        infos: list[tuple[int, int, int, int]] = []
        ds.id.chunk_iter(
            lambda si: infos.append((si.chunk_offset[0], si.filter_mask, si.byte_offset, si.size))
        )
        for start, mask, offset, size in infos:
            if mask != 0 or start >= n or offset + size > len(mapped):
                continue  # left to the slow path below
            raw = mapped[offset : offset + size]
            futures.append(pool.submit(decode_chunk, raw, out[start : start + clen], clen))
            done.add(start)
    for start in range(0, n, clen):
        if start in done:
            continue
        target = out[start : start + clen]
        try:
            mask, raw_bytes = ds.id.read_direct_chunk((start,))
        except (KeyError, OSError, RuntimeError):
            mask, raw_bytes = -1, b""  # chunk not allocated: let HDF5 supply the fill value
        if mask != 0:
            target[...] = ds[start : start + clen]
            continue
        futures.append(pool.submit(decode_chunk, raw_bytes, target, clen))
    if pending is None:
        wait_all(futures[first:])
    return out


def wait_all(futures: list[Future[None]]) -> None:
    """Wait for decoding futures; re-raise the first error."""
    for fut in futures:
        fut.result()


def wait_all_quietly(futures: list[Future[None]]) -> None:
    """Wait for decoding futures, ignoring their errors (used when already failing)."""
    for fut in futures:
        fut.exception()
