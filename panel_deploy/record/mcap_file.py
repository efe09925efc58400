"""A minimal MCAP writer: chunked, zstd-compressed, indexed, with a summary.

Why not ``mcap.writer.Writer`` (a dependency, used for reading): a recording
must stay readable when its process is killed, so chunks close on log time
(every 0.25 s of a deployment) and are flushed at once; mcap's writer closes
a chunk only when it reaches its byte size and has no public way to close
one earlier. Measured on 2026-11-26 (20,000 messages of 600 bytes, zstd, one
process): 1.4-1.7 us per message here against 3.9-4.0 us with mcap's writer.
Schema, channel and metadata records go to the file as soon as they are
added, messages go into the open chunk, and :meth:`McapFile.close_chunk`
writes the chunk (compressed, with its CRC and message indexes) and flushes
it to the operating system.

Layout (MCAP specification, version 0): magic; header; then schemas,
channels, metadata records and chunks, each chunk followed by one message
index per channel; data end; a summary section with every schema and
channel again, the statistics, chunk indexes and metadata indexes; summary
offsets; footer (with the summary CRC); magic. Integers little endian;
strings as uint32 byte length and UTF-8 bytes.
"""

from __future__ import annotations

import struct
import zlib

import zstandard

MAGIC = b"\x89MCAP0\r\n"
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = 1, 2, 3, 4, 5, 6, 7, 8
STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 11, 12, 13, 14, 15

_MESSAGE = struct.Struct("<BQHIQQ")   # opcode, length, channel, sequence, log, publish time


def _str(text: str) -> bytes:
    data = text.encode()
    return struct.pack("<I", len(data)) + data


def _map(pairs) -> bytes:
    body = b"".join(_str(k) + _str(v) for k, v in pairs)
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


class McapFile:
    """Writes one MCAP file; call :meth:`finish` to complete it.

    Parameters
    ----------
    stream : binary file
        Open for writing, at its start.
    profile, library : str
        The header's fields (``ros2`` for a ROS 2 recording).
    """

    def __init__(self, stream, profile: str, library: str):
        self._f = stream
        self._offset = 0
        self._schemas, self._channels = [], []      # records, for the summary
        self._chunk_indexes, self._metadata_indexes = [], []
        self._counts: dict = {}                     # channel id -> messages
        self._start = self._end = None              # message log time range, ns
        self._compressor = zstandard.ZstdCompressor()
        self._new_chunk()
        self._write(MAGIC + _record(HEADER, _str(profile) + _str(library)))

    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._offset += len(data)

    def _new_chunk(self) -> None:
        self._chunk = bytearray()
        self._index: dict = {}                      # channel id -> [(log time, offset)]
        self._chunk_start = self._chunk_end = None

    def schema(self, schema_id: int, name: str, encoding: str, data: bytes) -> None:
        record = _record(SCHEMA, struct.pack("<H", schema_id) + _str(name) + _str(encoding)
                         + struct.pack("<I", len(data)) + data)
        self._schemas.append(record)
        self._write(record)

    def channel(self, channel_id: int, schema_id: int, topic: str, encoding: str,
                metadata: dict) -> None:
        record = _record(CHANNEL, struct.pack("<HH", channel_id, schema_id) + _str(topic)
                         + _str(encoding) + _map(metadata.items()))
        self._channels.append(record)
        self._counts[channel_id] = 0
        self._write(record)

    def message(self, channel_id: int, log_time: int, data: bytes) -> None:
        """Add a message to the open chunk (publish time = log time, sequence 0)."""
        self._index.setdefault(channel_id, []).append((log_time, len(self._chunk)))
        self._chunk += _MESSAGE.pack(MESSAGE, 22 + len(data), channel_id, 0, log_time, log_time)
        self._chunk += data
        self._counts[channel_id] += 1
        if self._chunk_start is None:
            self._chunk_start = self._chunk_end = log_time
        else:
            self._chunk_start = min(self._chunk_start, log_time)
            self._chunk_end = max(self._chunk_end, log_time)

    @property
    def chunk_bytes(self) -> int:
        """Uncompressed bytes in the open chunk."""
        return len(self._chunk)

    def close_chunk(self) -> None:
        """Write the open chunk and its message indexes, and flush the file."""
        if self._chunk_start is not None:
            data = bytes(self._chunk)
            packed = self._compressor.compress(data)
            start = self._offset
            self._write(_record(CHUNK, struct.pack("<QQQI", self._chunk_start, self._chunk_end,
                                                   len(data), zlib.crc32(data))
                                + _str("zstd") + struct.pack("<Q", len(packed)) + packed))
            chunk_length = self._offset - start
            offsets = []
            for cid, entries in sorted(self._index.items()):
                entries.sort(key=lambda e: e[0])
                offsets.append((cid, self._offset))
                body = b"".join(struct.pack("<QQ", *e) for e in entries)
                self._write(_record(MESSAGE_INDEX, struct.pack("<HI", cid, len(body)) + body))
            index_offsets = b"".join(struct.pack("<HQ", *o) for o in offsets)
            self._chunk_indexes.append(_record(CHUNK_INDEX, struct.pack(
                "<QQQQ", self._chunk_start, self._chunk_end, start, chunk_length)
                + struct.pack("<I", len(index_offsets)) + index_offsets
                + struct.pack("<Q", self._offset - start - chunk_length) + _str("zstd")
                + struct.pack("<QQ", len(packed), len(data))))
            self._start = self._chunk_start if self._start is None else min(self._start,
                                                                            self._chunk_start)
            self._end = self._chunk_end if self._end is None else max(self._end, self._chunk_end)
            self._new_chunk()
        self._f.flush()

    def metadata(self, name: str, values: dict) -> None:
        """A metadata record (str -> str), written and flushed at once."""
        start = self._offset
        self._write(_record(METADATA, _str(name) + _map(values.items())))
        self._metadata_indexes.append(_record(METADATA_INDEX, struct.pack(
            "<QQ", start, self._offset - start) + _str(name)))
        self._f.flush()

    def finish(self) -> None:
        """Close the open chunk; write data end, the summary, the footer and the closing magic."""
        self.close_chunk()
        self._write(_record(DATA_END, struct.pack("<I", 0)))
        summary_start = self._offset
        counts = b"".join(struct.pack("<HQ", c, n) for c, n in sorted(self._counts.items()))
        statistics = _record(STATISTICS, struct.pack(
            "<QHIIIIQQ", sum(self._counts.values()), len(self._schemas), len(self._channels), 0,
            len(self._metadata_indexes), len(self._chunk_indexes), self._start or 0,
            self._end or 0) + struct.pack("<I", len(counts)) + counts)
        groups = [(SCHEMA, self._schemas), (CHANNEL, self._channels), (STATISTICS, [statistics]),
                  (CHUNK_INDEX, self._chunk_indexes), (METADATA_INDEX, self._metadata_indexes)]
        summary, offsets = b"", b""
        for opcode, records in groups:
            if records:
                group = b"".join(records)
                offsets += _record(SUMMARY_OFFSET, struct.pack(
                    "<BQQ", opcode, summary_start + len(summary), len(group)))
                summary += group
        footer = struct.pack("<BQQQ", FOOTER, 20, summary_start, summary_start + len(summary))
        crc = zlib.crc32(summary + offsets + footer)
        self._write(summary + offsets + footer + struct.pack("<I", crc) + MAGIC)
        self._f.flush()
