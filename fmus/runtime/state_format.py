"""The serialized FMU state: an explicit, versioned format that can only ever produce data.

``fmi2SerializeFMUstate`` / ``fmi3SerializeFMUState`` write, and the deserialize calls read, these
bytes (little-endian throughout) -- the one serialized form of an obsfmu FMU state, for both FMI
versions: the native binary keeps its own fields (FMI version, state machine state) in the payload
(:meth:`fmus.runtime.slave.BlockSlave.get_fmu_state`) and validates them when the state comes back::

    header   magic b"OBSFMUst" | format version u16 | 0 u16 | identity length u32 | payload length u64
    digest   SHA-256 of header + identity + payload (32 bytes)
    identity UTF-8: "<model name> <GUID (FMI 2.0) or instantiationToken (FMI 3.0) of the FMU>"
    payload  one value, encoded as below

A value is a one-byte tag and its content:

==== ===================================================================================
``N`` ``None``
``T`` ``True``; ``F`` ``False``
``i`` int: 8 bytes, signed
``f`` float: 8 bytes, IEEE 754
``s`` str: length u32, UTF-8
``l`` list, ``t`` tuple: count u32, then the items
``d`` dict: count u32, then per entry a key (length u32, UTF-8) and a value
``a`` array: dtype code u8 (0 float64, 1 int64, 2 bool, 3 complex128), ndim u8 (<= 32),
      ndim dimensions u64, then the elements in C order
==== ===================================================================================

A state is at most :data:`MAX_STATE_BYTES` (64 MiB; the native binary refuses a larger one before copying it,
``OBSFMU_MAX_STATE_BYTES``): a larger one is refused before anything is read, the checksum is tested before
any of the payload is decoded, and neither copies the bytes.

Decoding is total: any bytes give either the data or :class:`StateFormatError` with the
reason.  Every length and count is checked against the bytes that remain before anything is
allocated, nesting is limited, and nothing in the format can name a type, a module or a
function -- unlike pickle, the bytes cannot run code.  What the data *means* (does it fit
this FMU's block?) is checked when it is restored (:func:`observers.state.restore`).
"""

from __future__ import annotations

import hashlib
import struct

import numpy as np

__all__ = ["StateFormatError", "FORMAT_VERSION", "MAGIC", "MAX_STATE_BYTES", "pack", "unpack", "encode", "decode"]

MAGIC = b"OBSFMUst"
#: 2: the native binary's fields and the slave's "initialized" are part of the state
FORMAT_VERSION = 2
#: the largest state written or read (the obsfmu states are of kilobytes: fixed layouts, designs of at most 200
#: states, inputs and outputs); = OBSFMU_MAX_STATE_BYTES of fmus/native/obsfmu_native.h
MAX_STATE_BYTES = 64 << 20
_HEADER = struct.Struct("<8sHHIQ")
_DIGEST = 32
_MAX_IDENTITY = 4096
_MAX_DEPTH = 64
_MAX_NDIM = 32
_DTYPES = (np.dtype("<f8"), np.dtype("<i8"), np.dtype("|b1"), np.dtype("<c16"))
_U8, _U32, _U64 = struct.Struct("<B"), struct.Struct("<I"), struct.Struct("<Q")
_I64, _F64 = struct.Struct("<q"), struct.Struct("<d")


class StateFormatError(ValueError):
    """Bytes that are not a state of this FMU in this format; the message says why."""


# -------------------------------------------------------------------------------------- framing
def pack(identity: str, tree) -> bytes:
    """Header, digest, identity and the encoded ``tree``."""
    ident = identity.encode("utf-8")
    payload = encode(tree)
    header = _HEADER.pack(MAGIC, FORMAT_VERSION, 0, len(ident), len(payload))
    if len(header) + _DIGEST + len(ident) + len(payload) > MAX_STATE_BYTES:
        raise StateFormatError(_too_large(len(header) + _DIGEST + len(ident) + len(payload)))
    return header + hashlib.sha256(header + ident + payload).digest() + ident + payload


def unpack(data: bytes, identity: str):
    """The tree in ``data``, a state packed for ``identity``; :class:`StateFormatError` otherwise."""
    if len(data) > MAX_STATE_BYTES:
        raise StateFormatError(_too_large(len(data)) + ": refused before reading it")
    data = memoryview(data).cast("B")               # no copy: slices of it are views
    start = _HEADER.size + _DIGEST
    if len(data) < start:
        raise StateFormatError(f"truncated: {len(data)} bytes, an FMU state has at least {start}")
    magic, version, reserved, ident_size, payload_size = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise StateFormatError("not an obsfmu FMU state (wrong magic bytes)")
    if version != FORMAT_VERSION:
        raise StateFormatError(f"state format version {version}; this FMU reads version {FORMAT_VERSION}")
    if reserved != 0 or ident_size > _MAX_IDENTITY:
        raise StateFormatError("damaged header")
    if len(data) != start + ident_size + payload_size:
        raise StateFormatError(f"{len(data)} bytes, the header announces {start + ident_size + payload_size} "
                               f"(truncated or extended)")
    digest = hashlib.sha256(data[:_HEADER.size])
    digest.update(data[start:])                      # identity + payload
    if digest.digest() != data[_HEADER.size:start]:
        raise StateFormatError("checksum mismatch: the state bytes are damaged")
    try:
        found = bytes(data[start:start + ident_size]).decode("utf-8")
    except UnicodeDecodeError:
        raise StateFormatError("damaged identity") from None
    if found != identity:
        raise StateFormatError(f"this state belongs to another FMU ({found!r}), not to {identity!r}")
    return decode(data[start + ident_size:])


def _too_large(size: int) -> str:
    return f"{size} bytes; an obsfmu FMU state has at most {MAX_STATE_BYTES} (64 MiB, MAX_STATE_BYTES)"


# -------------------------------------------------------------------------------------- payload
def encode(value) -> bytes:
    """The payload bytes of ``value`` (a tree of the types in the module docstring)."""
    out: list[bytes] = []
    _encode(value, out, 0)
    return b"".join(out)


def _encode(value, out: list, depth: int) -> None:
    if depth > _MAX_DEPTH:
        raise StateFormatError(f"nested deeper than {_MAX_DEPTH}")
    kind = type(value)
    if value is None:
        out.append(b"N")
    elif kind is bool:
        out.append(b"T" if value else b"F")
    elif kind is int:
        if not -2 ** 63 <= value < 2 ** 63:
            raise StateFormatError(f"integer {value} does not fit 64 bits")
        out.append(b"i" + _I64.pack(value))
    elif kind is float:
        out.append(b"f" + _F64.pack(value))
    elif kind is str:
        out.append(b"s")
        _string(value, out)
    elif kind is list or kind is tuple:
        out.append((b"l" if kind is list else b"t") + _U32.pack(len(value)))
        for item in value:
            _encode(item, out, depth + 1)
    elif kind is dict:
        out.append(b"d" + _U32.pack(len(value)))
        for key, item in value.items():
            if type(key) is not str:
                raise StateFormatError(f"dictionary key {key!r} is not a string")
            _string(key, out)
            _encode(item, out, depth + 1)
    elif kind is np.ndarray:
        code = next((i for i, dtype in enumerate(_DTYPES) if dtype == value.dtype), None)
        if code is None or value.ndim > _MAX_NDIM:
            raise StateFormatError(f"array of dtype {value.dtype} and {value.ndim} dimensions not allowed")
        out.append(b"a" + _U8.pack(code) + _U8.pack(value.ndim) + b"".join(_U64.pack(n) for n in value.shape))
        out.append(np.ascontiguousarray(value, dtype=_DTYPES[code]).tobytes())
    else:
        raise StateFormatError(f"a {kind.__name__} cannot be written to an FMU state")


def _string(text: str, out: list) -> None:
    raw = text.encode("utf-8")
    out.append(_U32.pack(len(raw)) + raw)


def decode(payload: bytes):
    """The value encoded in ``payload``; :class:`StateFormatError` for any other bytes."""
    reader = _Reader(payload)
    try:
        value = reader.value(0)
    except StateFormatError:
        raise
    except (struct.error, ValueError, OverflowError, UnicodeDecodeError) as exc:   # belt and braces
        raise StateFormatError(f"damaged payload at byte {reader.position}: {exc}") from None
    if reader.position != len(payload):
        raise StateFormatError(f"{len(payload) - reader.position} unexpected bytes after the payload")
    return value


class _Reader:
    def __init__(self, data: bytes):
        self.data = memoryview(data)
        self.position = 0

    def take(self, count: int) -> memoryview:
        if count > len(self.data) - self.position:
            raise StateFormatError(f"truncated payload: {count} bytes needed at byte {self.position}, "
                                   f"{len(self.data) - self.position} left")
        chunk = self.data[self.position:self.position + count]
        self.position += count
        return chunk

    def number(self, unpacker: struct.Struct):
        return unpacker.unpack(self.take(unpacker.size))[0]

    def count(self, least_bytes_each: int) -> int:
        """A u32 count, checked against the bytes left (each item needs at least that many)."""
        count = self.number(_U32)
        if count * least_bytes_each > len(self.data) - self.position:
            raise StateFormatError(f"count {count} at byte {self.position} exceeds the bytes left")
        return count

    def string(self) -> str:
        size = self.number(_U32)
        try:
            return bytes(self.take(size)).decode("utf-8")
        except UnicodeDecodeError:
            raise StateFormatError(f"invalid UTF-8 before byte {self.position}") from None

    def value(self, depth: int):
        if depth > _MAX_DEPTH:
            raise StateFormatError(f"nested deeper than {_MAX_DEPTH}")
        tag = bytes(self.take(1))
        if tag == b"N":
            return None
        if tag == b"T":
            return True
        if tag == b"F":
            return False
        if tag == b"i":
            return self.number(_I64)
        if tag == b"f":
            return self.number(_F64)
        if tag == b"s":
            return self.string()
        if tag in (b"l", b"t"):
            items = [self.value(depth + 1) for _ in range(self.count(1))]
            return items if tag == b"l" else tuple(items)
        if tag == b"d":
            result = {}
            for _ in range(self.count(5)):
                key = self.string()
                if key in result:
                    raise StateFormatError(f"duplicate key {key!r}")
                result[key] = self.value(depth + 1)
            return result
        if tag == b"a":
            return self.array()
        raise StateFormatError(f"unknown tag {tag!r} at byte {self.position - 1}")

    def array(self) -> np.ndarray:
        code, ndim = self.number(_U8), self.number(_U8)
        if code >= len(_DTYPES) or ndim > _MAX_NDIM:
            raise StateFormatError(f"array of dtype code {code} and {ndim} dimensions not allowed")
        dtype = _DTYPES[code]
        shape = tuple(self.number(_U64) for _ in range(ndim))
        size = 1
        for n in shape:
            size *= n
        raw = self.take(size * dtype.itemsize)             # checked against the bytes left first
        if code == 2 and np.frombuffer(raw, dtype=np.uint8).max(initial=0) > 1:
            raise StateFormatError("boolean array with values other than 0 and 1")
        return np.frombuffer(raw, dtype=dtype).reshape(shape).astype(dtype.newbyteorder("="), copy=True)
