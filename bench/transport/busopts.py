"""The settings python-can gets besides interface and channel: bitrate, CAN FD, and bench.toml's [bus] table.

Why one place: `bench run`, `plant`, `monitor`, `replay` and the pytest plugin open buses alike, and the
default bitrate is the contract's (the databases' `Baudrate` attribute), not whatever the adapter or
python-can's config file happens to hold. Precedence: command line, then [bus], then the databases.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from bench.errors import ConfigError

#: BusType attribute values (Vector's convention) that mean the contract's bus is CAN FD.
FD_BUS_TYPES = frozenset({"CAN FD", "CANFD", "CAN_FD"})


@dataclass(frozen=True)
class BusOptions:
    """What a bus is opened with; None = not given at this level (a lower level or python-can decides)."""

    bitrate: int | None = None
    fd: bool | None = None
    data_bitrate: int | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)   # further python-can arguments ([bus] table)

    def over(self, lower: BusOptions) -> BusOptions:
        """These options where given, `lower`'s elsewhere."""
        return BusOptions(bitrate=self.bitrate if self.bitrate is not None else lower.bitrate,
                          fd=self.fd if self.fd is not None else lower.fd,
                          data_bitrate=self.data_bitrate if self.data_bitrate is not None else lower.data_bitrate,
                          extra={**lower.extra, **self.extra})

    def kwargs(self) -> dict[str, Any]:
        """The keyword arguments for `can.Bus(interface=..., channel=..., **kwargs)`."""
        out = dict(self.extra)
        if self.bitrate is not None:
            out["bitrate"] = self.bitrate
        if self.fd is not None:
            out["fd"] = self.fd
        if self.data_bitrate is not None:
            out["data_bitrate"] = self.data_bitrate
        return out

    def check(self) -> None:
        """Combinations no interface can honour, named as the user gave them."""
        if self.data_bitrate is not None and not self.fd:
            raise ConfigError(f"--data-bitrate {self.data_bitrate}: a data-phase bitrate needs CAN FD "
                              "(--fd, or fd = true in [bus])")


def positive_int(where: str, value: Any) -> int:
    """A bitrate: a positive whole number (TOML and the command line give ints; bool is not one)."""
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise ConfigError(f"{where} must be a positive whole number of bit/s, got {value!r}")
    return value


def contract_options(databases: Iterable[tuple[str, Any]]) -> BusOptions:
    """The bus the databases describe: `BA_ "Baudrate"` and, when `BA_ "BusType"` says CAN FD, fd=True.
    Databases that disagree are an error (they describe one bus); a database without them says nothing."""
    found: dict[str, tuple[str, Any]] = {}
    for name, db in databases:
        attributes = getattr(getattr(db, "dbc", None), "attributes", None) or {}
        for key in ("Baudrate", "BusType"):
            attribute = attributes.get(key)
            value = getattr(attribute, "value", None)
            if value in (None, "", 0):
                continue
            if key in found and found[key][1] != value:
                raise ConfigError(f"databases disagree on the bus: {found[key][0]} has {key} {found[key][1]!r}, "
                                  f"{name} has {value!r}")
            found.setdefault(key, (name, value))
    bitrate = found.get("Baudrate", ("", None))[1]
    if bitrate is not None:
        bitrate = positive_int(f"{found['Baudrate'][0]}: attribute Baudrate", bitrate)
    bus_type = str(found.get("BusType", ("", ""))[1]).strip().upper()
    return BusOptions(bitrate=bitrate, fd=True if bus_type in FD_BUS_TYPES else None)
