"""The kernel's ISO-TP (Linux CAN_ISOTP, through can-isotp's socket) as the tester's endpoint on SocketCAN.

On a socketcan bus whose kernel has CAN_ISOTP, the tester's segmentation, flow control and N_Bs/N_Cr timers are
the kernel's, as in a supplier's Linux tester (udsoncan's IsoTPSocketConnection): the exchange then shows that an
ECU talks to the ISO-TP every Linux tester has, not only to the bench's own (bench/diag/isotp.py, which stays for
every other bus and for the simulated nodes' servers). The frames still reach the bench's raw socket, so the
monitor judges their framing as before. `BENCH_KERNEL_ISOTP=0` keeps the bench's own.

The endpoint has the shape of `IsoTpEndpoint` that the tester's connection uses (transmit, received, problems,
busy, params); the kernel reports a broken exchange as a socket error, turned here into the same problem records.
"""

from __future__ import annotations

import errno
import os
import socket
from collections import deque

import isotp

from bench import canid
from bench.diag.isotp import IsoTpParams, IsoTpProblem

#: the kernel's socket errors of an exchange (linux/net/can/isotp.c) as the rules of bench.diag.isotp.RULES
KERNEL_ERRORS = {
    errno.ETIMEDOUT: "N_Cr timeout",            # no consecutive frame in time
    errno.ECOMM: "N_Bs timeout",                # no flow control in time after our first frame
    errno.EILSEQ: "sequence number",            # a consecutive frame with the wrong SN
    errno.EBADMSG: "length",                    # a malformed frame, or a flow control with a reserved status
    errno.EMSGSIZE: "flow control overflow",    # the receiver answered FC OVFLW
}

_MTU = 4095


def kernel_isotp_available() -> bool:
    """Whether this kernel opens ISO-TP sockets (CONFIG_CAN_ISOTP) and BENCH_KERNEL_ISOTP is not 0."""
    if os.environ.get("BENCH_KERNEL_ISOTP", "1") == "0" or not hasattr(socket, "CAN_ISOTP"):
        return False
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_DGRAM, socket.CAN_ISOTP).close()
    except OSError:
        return False
    return True


class KernelIsoTpEndpoint:
    """One tester connection on a kernel ISO-TP socket bound to `channel` (open from `open()` to `close()`)."""

    #: never mid-message as the connection sees it: the kernel hands over whole messages or an error
    busy = False

    def __init__(self, channel: str, tx_id: int, rx_id: int, params: IsoTpParams) -> None:
        self.channel, self.tx_id, self.rx_id, self.params = channel, tx_id, rx_id, params
        self.received: deque[tuple[float, bytes]] = deque()
        self.problems: list[IsoTpProblem] = []
        self._socket: socket.socket | None = None
        self._t = 0.0

    def open(self) -> None:
        sock = isotp.socket()   # can-isotp's: it sets the kernel's options (padding, flow control) by name
        sock.set_opts(txpad=self.params.padding)
        sock.set_fc_opts(bs=self.params.block_size, stmin=round(self.params.stmin * 1000))
        mode = isotp.AddressingMode.Normal_29bits if canid.is_extended(self.tx_id) \
            else isotp.AddressingMode.Normal_11bits
        sock.bind(self.channel, isotp.Address(mode, txid=canid.arbitration_id(self.tx_id),
                                              rxid=canid.arbitration_id(self.rx_id)))
        self._socket = sock.real_socket()   # (can-isotp's own object keeps no state beyond it)
        self._socket.setblocking(False)

    def close(self) -> None:
        if self._socket is not None:
            self._socket.close()
            self._socket = None

    def transmit(self, t: float, payload: bytes) -> None:
        """Hand a request to the kernel (it segments it and waits for the ECU's flow control on its own)."""
        self._t = t
        self._read(t)   # an earlier exchange's error is that exchange's, recorded before this one starts
        assert self._socket is not None, "transmit before open"
        try:
            self._socket.send(payload)
        except OSError as exc:
            self._problem(t, exc, "sending")

    def on_frame(self, t: float, data: bytes) -> None:
        """The kernel receives the node's frames itself."""

    def poll(self, t: float) -> None:
        self._read(t)

    def _read(self, t: float) -> None:
        sock = self._socket
        while sock is not None:
            try:
                payload = sock.recv(_MTU)
            except BlockingIOError:
                return
            except OSError as exc:
                self._problem(t, exc, "receiving")
                continue
            self.received.append((t, payload))

    def _problem(self, t: float, exc: OSError, doing: str) -> None:
        rule = KERNEL_ERRORS.get(exc.errno or 0, "length")
        self.problems.append(IsoTpProblem(t, rule, f"the kernel's ISO-TP socket on {self.channel} "
                                                   f"({canid.text(self.tx_id)} → {canid.text(self.rx_id)}) failed "
                                                   f"{doing}: {os.strerror(exc.errno or 0)}"))
