"""A child process of a test (`bench plant`, an example ECU) whose output is read as it comes, so that a test
waits for the line that says the child is ready instead of sleeping a guessed time: on a loaded machine
`bench plant` took more than the 1.0 s the tests used to sleep before it opened its bus."""

from __future__ import annotations

import signal
import subprocess
import threading
import time
from collections.abc import Sequence
from pathlib import Path


class Child:
    """A process whose stdout and stderr (merged) a thread collects line by line until it ends."""

    def __init__(self, argv: Sequence[str], cwd: Path) -> None:
        self.process = subprocess.Popen(list(argv), cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        text=True)
        self._lines: list[str] = []
        self._changed = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            with self._changed:
                self._lines.append(line)
                self._changed.notify_all()
        with self._changed:
            self._lines.append("")          # end of output: the child closed it (it ended)
            self._changed.notify_all()

    @property
    def output(self) -> str:
        with self._changed:
            return "".join(self._lines)

    def wait_for(self, marker: str, seconds: float) -> str:
        """The output up to and with the first line that contains `marker`; fails when the child ends or
        `seconds` pass without it (a bound on start-up only, generous: it never judges the product)."""
        deadline = time.monotonic() + seconds
        with self._changed:
            while True:
                for i, line in enumerate(self._lines):
                    if marker in line:
                        return "".join(self._lines[: i + 1])
                ended = bool(self._lines) and self._lines[-1] == ""
                left = deadline - time.monotonic()
                if ended or left <= 0:
                    raise AssertionError(f"no {marker!r} from {self.process.args} "
                                         f"({'it ended' if ended else f'within {seconds:g} s'}):\n"
                                         + "".join(self._lines))
                self._changed.wait(left)

    def stop(self, timeout: float = 30.0) -> str:
        """Ctrl-C (SIGINT) if it still runs, wait for it to end and return its whole output; kills it when it
        does not end within `timeout` (no child outlives its test)."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
        try:
            self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            raise
        finally:
            self._reader.join(timeout=10)
        return self.output

    @property
    def returncode(self) -> int | None:
        return self.process.returncode
