"""RFC 6455 payload masking, shared by the server's fast unmask and the Unity-wire client."""

from __future__ import annotations

import numpy as np


def xor_mask(data: bytes, mask: bytes | bytearray, length: int | None = None, offset: int = 0) -> bytes:
    """XOR the first ``length`` bytes of ``data`` with the 4-byte WebSocket ``mask`` (section 5.3).

    ``offset`` is the mask position of ``data[0]`` (a frame may arrive in several recv chunks).
    Vectorised over native uint32 words, the mask viewed as the same native word, so byte order is
    consistent on any endianness; the 0-3 trailing bytes are done one by one.
    """
    if length is None:
        length = len(data)
    rot = offset & 3
    key = bytes(mask[rot:4]) + bytes(mask[:rot])
    out = bytearray(length)
    n4 = length >> 2
    if n4:
        np.bitwise_xor(np.frombuffer(data, np.uint32, n4), np.frombuffer(key, np.uint32)[0],
                       out=np.frombuffer(out, np.uint32, n4))
    for i in range(n4 << 2, length):
        out[i] = data[i] ^ key[i & 3]
    return bytes(out)
