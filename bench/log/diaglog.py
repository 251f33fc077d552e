"""The run log's diagnostic topics: each whole UDS message of the bus, as `/diag/<Message>` (format.DIAG_SCHEMA).

A Foxglove user reads "ReadDTCInformation 0x02" and "positive ReadDTCInformation: C1C05-87 status 0x2F" instead of
raw ISO-TP frames. The frames are reassembled by the monitor's own framing check (bench.diag.isotp.IsoTpFraming,
one per connection, each identifier in exactly one) and described by bench.diag.describe, so the log reads the
bus as the monitor judges it. Imported only by the log process (bench.log.logproc): udsoncan's import costs the
bench's process nothing,
and the log process pays it only once the bus carries a UDS message.
"""

from __future__ import annotations

from bench.database.codec import Codebook
from bench.diag.declaration import Declaration, NodeDiagnostics
from bench.diag.isotp import IsoTpFraming, IsoTpParams
from bench.log.recorder import Recorder

#: Without a declaration: a physical request's response id is the request's + 8 (ISO 15765-4's 0x7E0 -> 0x7E8)
RESPONSE_OFFSET = 8


class DiagnosticLog:
    """Follows every diagnostic connection of the databases and writes each whole message to the recorder.

    The connections are the declaration's (each node's request and response, the functional request alone); a
    project without one gets its databases' diagnostic messages, a request paired with the response 8 above it and
    the node from that response's sender (DTCs then as codes only, without their names)."""

    def __init__(self, recorder: Recorder, codebook: Codebook, declaration: Declaration | None) -> None:
        self._recorder = recorder
        self._framing: dict[int, IsoTpFraming] = {}
        #: data id -> (DBC message, node, direction, the node's declaration)
        self._about: dict[int, tuple[str, str, str, NodeDiagnostics | None]] = {}
        codecs = codebook.by_id
        if declaration is not None:
            protocol = declaration.protocol
            params = IsoTpParams(padding=protocol.padding, n_bs=protocol.n_bs, n_cr=protocol.n_cr)
            for node in declaration.nodes.values():
                self._follow(node.request, node.response, params)
                for frame_id, direction in ((node.request, "request"), (node.response, "response")):
                    if frame_id in codecs:
                        self._about[frame_id] = (codecs[frame_id].name, node.node, direction, node)
            functional = protocol.functional_request
            self._follow(functional, functional, params)
            if functional in codecs:
                self._about[functional] = (codecs[functional].name, "", "functional", None)
        else:
            diagnostic = {i: c for i, c in codecs.items() if c.diagnostic}
            for frame_id, codec in sorted(diagnostic.items()):
                partner = diagnostic.get(frame_id + RESPONSE_OFFSET)
                if codec.diagnostic == "request" and partner is not None and partner.diagnostic == "response":
                    self._follow(frame_id, partner.frame_id, IsoTpParams())
                    sender = partner.senders[0] if partner.senders else ""
                    self._about[frame_id] = (codec.name, sender, "request", None)
                    self._about[partner.frame_id] = (partner.name, sender, "response", None)
            for frame_id, codec in diagnostic.items():
                if frame_id not in self._framing:
                    self._follow(frame_id, frame_id, IsoTpParams())
                    sender = codec.senders[0] if codec.diagnostic == "response" and codec.senders else ""
                    self._about[frame_id] = (codec.name, sender, codec.diagnostic, None)
        self.ids = frozenset(self._framing)

    def _follow(self, a_id: int, b_id: int, params: IsoTpParams) -> None:
        framing = IsoTpFraming(a_id, b_id, params, on_message=self._message)
        self._framing[a_id] = self._framing[b_id] = framing

    def on_frame(self, t: float, frame_id: int, data: bytes) -> None:
        """A frame of the bus (of any id); the message it completes goes to the log at once (LogError: refused)."""
        framing = self._framing.get(frame_id)
        if framing is not None:
            framing.on_frame(t, frame_id, data)

    def _message(self, t: float, data_id: int, payload: bytes) -> None:
        about = self._about.get(data_id)
        if about is None:   # a declared id that is no message of the databases: nowhere to log it
            return
        from bench.diag.describe import describe, service_name  # udsoncan (0.3 s) once a log has UDS in it

        message, node, direction, diagnostics = about
        sid = payload[0]
        self._recorder.diagnostic(t, message, {
            "node": node, "direction": direction,
            "service": service_name(payload[1] if sid == 0x7F and len(payload) > 1 else sid),
            "text": describe(payload, diagnostics), "data": payload.hex(" ").upper(), "length": len(payload),
        })
