"""pytest plugin for python-can's own test files: swaps in the bench's bus, skips what the bench documents otherwise.

Loaded by scripts/python-can-suite (`-p tests.pycan_compat.plugin`). The test files stay as python-can ships
them: they open buses by the interface name "virtual", which this plugin points at the bench's
`embedded` (bench.transport.embedded:VirtualTimeBus); python-can's own virtual bus cannot be opened at all while it
runs, so a test that silently ran on it would fail, not pass. The `.mcap` format comes in through
mcap_format.py (a ReaderWriterTest subclass, as python-can declares its formats).
"""

from __future__ import annotations

from typing import Any

import pytest

SWAPPED = "virtual"
BENCH_INTERFACE = "embedded"

#: The one list of skips: test id (file::Class::test) -> why the bench differs (one line, printed by -rs).
SKIPS: dict[str, str] = {
    "back2back_test.py::Back2BackTestCase::test_timestamp_is_absolute":
        "the embedded bus keeps the sender's (virtual) timestamp; it never stamps the wall clock",
    "back2back_test.py::TestThreadSafeBus::test_timestamp_is_absolute":
        "the embedded bus keeps the sender's (virtual) timestamp; it never stamps the wall clock",
    "back2back_test.py::Back2BackTestCase::test_sub_second_timestamp_resolution":
        "the embedded bus keeps the sender's (virtual) timestamp; it never stamps the wall clock",
    "back2back_test.py::TestThreadSafeBus::test_sub_second_timestamp_resolution":
        "the embedded bus keeps the sender's (virtual) timestamp; it never stamps the wall clock",
    "back2back_test.py::Back2BackTestCase::test_timestamp":
        "the embedded bus keeps the sender's (virtual) timestamp; it never stamps the wall clock",
    "back2back_test.py::TestThreadSafeBus::test_timestamp":
        "the embedded bus keeps the sender's (virtual) timestamp; it never stamps the wall clock",
}

#: Test files whose classes other than these are python-can's own interfaces (socketcan, udp_multicast, etas):
#: not the bench's, so not collected here.
BENCH_CLASSES = {"back2back_test.py": {"Back2BackTestCase", "TestThreadSafeBus"}}


def _not_the_bench(*args: object, **kwargs: object) -> Any:
    """Stands in for python-can's virtual bus class while the plugin runs: opening it is an error."""
    raise AssertionError("python-can's own virtual bus was opened; the swap to the embedded bus missed it")


opened = 0   # bench buses opened during the run: none means the swap did not happen


def _swap() -> None:
    """Point the interface name "virtual" at the bench's bus; count the bench buses opened."""
    import can.interfaces
    import can.interfaces.virtual

    from bench.transport import VirtualTimeBus

    backends = can.interfaces.BACKENDS
    if backends.get(BENCH_INTERFACE) != ("bench.transport.embedded", "VirtualTimeBus"):
        raise pytest.UsageError(f"python-can does not know the interface {BENCH_INTERFACE!r}: "
                                "is the bench installed (pip install -e .)?")
    backends[SWAPPED] = backends[BENCH_INTERFACE]      # interface="virtual" now opens the embedded bus
    can.interfaces.virtual.VirtualBus = _not_the_bench   # type: ignore[assignment]  # nothing opens python-can's
    original = VirtualTimeBus.__init__

    def counting_init(self: VirtualTimeBus, *args: Any, **kwargs: Any) -> None:
        global opened
        opened += 1
        original(self, *args, **kwargs)

    VirtualTimeBus.__init__ = counting_init  # type: ignore[method-assign]


def _test_id(item: pytest.Item) -> str:
    parts = item.nodeid.split("::")
    return "::".join([parts[0].rsplit("/", 1)[-1], *parts[1:]])


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config, items: list[pytest.Item]) -> None:
    # Here, not at configure: pytest imports this plugin before it captures output, and can.Printer binds
    # sys.stdout when python-can is imported; a test that stops a Printer would then close pytest's own stdout.
    _swap()
    kept, dropped = [], []
    for item in items:
        file, cls = (_test_id(item).split("::") + [""])[:2]
        wanted = BENCH_CLASSES.get(file)
        if wanted is not None and cls not in wanted:
            dropped.append(item)
            continue
        reason = SKIPS.get(_test_id(item))
        if reason is not None:
            item.add_marker(pytest.mark.skip(reason=f"bench: {reason}"))
        kept.append(item)
    files = {_test_id(item).split("::")[0] for item in kept}
    unknown = {test for test in set(SKIPS) - {_test_id(item) for item in kept} if test.split("::")[0] in files}
    if unknown and not config.getoption("keyword") and not config.getoption("markexpr"):
        raise pytest.UsageError(f"the skip list names tests that do not exist: {sorted(unknown)}")
    if dropped:
        config.hook.pytest_deselected(items=dropped)
    items[:] = kept


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, exitstatus: int, config: pytest.Config) -> None:
    import can

    terminalreporter.write_line(f"python-can {can.__version__}: interface {SWAPPED!r} swapped for "
                                f"{BENCH_INTERFACE!r}; bench buses opened: {opened}")


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if opened == 0 and session.testscollected and not session.config.getoption("keyword"):
        session.exitstatus = pytest.ExitCode.TESTS_FAILED   # the swap never happened: the run proves nothing
