"""Image dimensions read from the JPEG (or PNG) header, WITHOUT decoding: the size check before the decode.

Why: a few hundred bytes of JPEG can claim 30000x30000 pixels, and libjpeg allocates and decodes all
of them (seconds of CPU, gigabytes of memory) before the decoded size can be compared with 320x160.
Reading the start-of-frame marker costs microseconds and refuses such a frame before any pixel exists.
Standard library only.
"""

from __future__ import annotations

import struct

from protocol.errors import ProtocolError

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
#: Start-of-frame markers (baseline, extended, progressive, lossless, arithmetic): C0..CF except the
#: tables and extension markers C4 (DHT), C8 (JPG) and CC (DAC).
_SOF_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
#: Markers without a length field (TEM, RST0..7): skipped on their own.
_STANDALONE = frozenset([0x01, *range(0xD0, 0xD8)])


def image_size(raw: bytes) -> tuple[int, int]:
    """``(width, height)`` claimed by a JPEG's start-of-frame marker or a PNG's IHDR chunk.

    Raises ``ProtocolError`` if the header is cut short, malformed, or has no frame before the scan.
    """
    if raw.startswith(_PNG_MAGIC):
        if len(raw) < 24 or raw[12:16] != b"IHDR":
            raise ProtocolError("image: PNG header cut short or without IHDR", field="image")
        width, height = struct.unpack_from(">II", raw, 16)
        return width, height
    if not raw.startswith(b"\xff\xd8"):
        raise ProtocolError(f"image: not a JPEG (starts with {raw[:4]!r})", field="image")
    pos, n = 2, len(raw)
    while pos + 4 <= n:
        if raw[pos] != 0xFF:
            raise ProtocolError(f"image: corrupt JPEG header (no marker at byte {pos})", field="image")
        marker = raw[pos + 1]
        if marker == 0xFF:  # fill byte before a marker
            pos += 1
            continue
        if marker in _STANDALONE:
            pos += 2
            continue
        if marker in (0xD9, 0xDA):  # end of image or start of scan before any frame header
            break
        (length,) = struct.unpack_from(">H", raw, pos + 2)
        if length < 2:
            raise ProtocolError(f"image: corrupt JPEG header (segment length {length} at byte {pos})",
                                field="image")
        if marker in _SOF_MARKERS:
            if pos + 9 > n:
                break
            height, width = struct.unpack_from(">HH", raw, pos + 5)
            return width, height
        pos += 2 + length
    raise ProtocolError(f"image: JPEG without a frame header ({n} bytes)", field="image")


def require_size(raw: bytes, width: int, height: int, what: str = "image") -> None:
    """Refuse an image whose header does not claim exactly ``width`` x ``height`` (before decoding it)."""
    try:
        w, h = image_size(raw)
    except ProtocolError as exc:
        raise ProtocolError(str(exc).replace("image:", f"{what}:", 1), field=exc.field) from None
    if (w, h) != (width, height):
        raise ProtocolError(f"{what}: expected {width}x{height}, got {w}x{h} (refused before decoding)",
                            field="image")
