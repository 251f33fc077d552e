"""AUTOSAR end-to-end protection (docs/spec/e2e.md): profiles 1, 2, 5 and 11 through the `autosar-e2e` library,
the E2E state machine, where each message's parameters come from, and the two-senders finding.

One implementation for the sender (restbus) and the receiver (monitor), so that sending and checking can never
disagree (the opendbc packer/parser idea); and the library an ECU's stack would use for the bytes.
"""

from bench.e2e.config import PARAMETERS, ProtectionError, protection
from bench.e2e.profiles import PROFILES, Field, Protection, SMConfig
from bench.e2e.receiver import Receiver, SMState, StateMachine, Status
from bench.e2e.senders import SenderTracker

__all__ = ["PARAMETERS", "PROFILES", "Field", "Protection", "ProtectionError", "Receiver", "SMConfig", "SMState",
           "SenderTracker", "StateMachine", "Status", "protection"]
