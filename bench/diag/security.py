"""The documented seed/key algorithm of SecurityAccess level 1 (docs/contract/diagnostics.md DIAG-SEC-01).

One function for the bench's simulated nodes and its tester. A real ECU's algorithm is its supplier's secret: the
tester takes it from bench.toml instead (bench.diag.tester.key_function).
"""

from __future__ import annotations

KEY_MASK = 0xA5A5A5A5


def rotl32(value: int, bits: int) -> int:
    value &= 0xFFFFFFFF
    return ((value << bits) | (value >> (32 - bits))) & 0xFFFFFFFF


def documented_key(seed: bytes, constant: int) -> bytes:
    """key = rotl32(seed XOR constant, 7) XOR 0xA5A5A5A5, 4 bytes big-endian (a seed of 4 bytes, big-endian)."""
    number = int.from_bytes(seed[-4:].rjust(4, b"\0"), "big")
    return (rotl32(number ^ constant, 7) ^ KEY_MASK).to_bytes(4, "big")
