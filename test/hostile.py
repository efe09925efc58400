"""Hostile files built on demand (issue 26), for the tests and the fuzz.

* :func:`alias_bomb`, :func:`alias_flow`: a few hundred bytes of YAML whose
  aliases expand to ``width ** levels`` values (billion laughs).
* :func:`npy_declaring`: a ``.npy`` member whose header declares a shape its
  data does not hold; :func:`npz_with` puts it into a copy of an ``.npz``.
* :func:`mcap_with_chunk`: an MCAP file whose one chunk declares an
  uncompressed size, holding compressed zeros of another size.
* :func:`file_size_limit`: a child process's ``ulimit -f``.
"""

from __future__ import annotations

import io
import resource
import struct
import zipfile

import numpy as np
import zstandard

from panel_deploy.record import mcap_file


def alias_flow(levels: int = 9, width: int = 9) -> str:
    """A YAML flow list: anchor ``a0`` (a string), then ``a1`` ... ``a<levels>``,
    each a list of ``width`` aliases of the one before."""
    items = ['&a0 "lol"'] + [f"&a{i} [{', '.join([f'*a{i - 1}'] * width)}]"
                             for i in range(1, levels + 1)]
    return f"[{', '.join(items)}]"


def alias_bomb(levels: int = 9, width: int = 9, key: str = "description") -> str:
    """A YAML mapping of ``key`` to :func:`alias_flow`."""
    return f"{key}: {alias_flow(levels, width)}\n"


def npy_declaring(shape, data: bytes = b"", dtype: str = "<f8") -> bytes:
    """A ``.npy`` file whose header declares ``shape`` of ``dtype``, followed by ``data``."""
    f = io.BytesIO()
    np.lib.format.write_array_header_1_0(f, {"descr": dtype, "fortran_order": False,
                                             "shape": tuple(shape)})
    return f.getvalue() + data


def npz_with(npz: bytes, name: str, member: bytes) -> bytes:
    """A copy of the archive ``npz`` with member ``name`` (``t.npy``) replaced by ``member``."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(npz)) as src, \
            zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info.filename, member if info.filename == name else src.read(info))
    return out.getvalue()


def mcap_with_chunk(declared: int, zeros: int, compression: str = "zstd") -> bytes:
    """Magic, header and one chunk of ``zeros`` zero bytes compressed with
    ``compression`` (zstd or lz4) declaring ``declared`` bytes (CRC 0: none to
    check); no footer."""
    block = bytes(min(zeros, 1 << 20))  # compressed piece by piece: 1 GiB is never in memory
    if compression == "zstd":
        compressor = zstandard.ZstdCompressor().compressobj()
        parts = []
    else:
        import lz4.frame
        compressor = lz4.frame.LZ4FrameCompressor()
        parts = [compressor.begin()]
    for start in range(0, zeros, len(block) or 1):
        parts.append(compressor.compress(block[:zeros - start]))
    packed = b"".join(parts) + compressor.flush()
    body = (struct.pack("<QQQI", 0, 0, declared, 0) + mcap_file._str(compression)
            + struct.pack("<Q", len(packed)) + packed)
    return (mcap_file.MAGIC + mcap_file._record(mcap_file.HEADER, mcap_file._str("ros2")
                                                + mcap_file._str("hostile"))
            + mcap_file._record(mcap_file.CHUNK, body))



def file_size_limit(limit):
    """``preexec_fn`` of a child whose files may not grow beyond ``limit`` bytes
    (``ulimit -f``; Python ignores SIGXFSZ, so a write past it fails with EFBIG)."""
    if limit is None:
        return None
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
