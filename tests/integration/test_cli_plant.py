"""`bench plant`'s status lines say why frames were invalid, not only how many."""

from __future__ import annotations

from rich.console import Console

from bench.cli.plant import INVALID_SHOWN, _report_invalid
from bench.codec import load_codebook
from bench.config import load_config
from bench.monitor import Monitor


def test_new_invalid_frames_are_described_once() -> None:
    codebook = load_codebook(load_config().databases)
    monitor = Monitor(codebook)
    codec = codebook["BENCH_Control"]
    console = Console(record=True, width=200)
    for t in (0.1, 0.2):
        monitor.on_frame(t, codec.frame_id, bytes(codec.length - 1), "rx")   # one byte short
    shown = _report_invalid(console, monitor, 0)
    text = console.export_text()
    assert shown == 2
    assert text.count(f"BENCH_Control (0x{codec.frame_id:X}): length {codec.length - 1}, DBC says {codec.length}") == 2
    assert _report_invalid(console, monitor, shown) == 2 and console.export_text() == ""   # nothing new
    for i in range(INVALID_SHOWN + 2):
        monitor.on_frame(1.0 + i, 0x7FF, b"", "rx")   # unknown identifier
    _report_invalid(console, monitor, shown)
    text = console.export_text()
    assert text.count("unknown identifier") == INVALID_SHOWN and "... and 2 more" in text
