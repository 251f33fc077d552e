"""Where a message's E2E protection comes from: DBC attributes, ARXML (cantools' E2E properties), bench.toml.

Each parameter has one name, AUTOSAR's: the DBC attribute is that name with the prefix `E2E_`
(`E2E_Profile`, `E2E_DataID`, `E2E_MaxDeltaCounter`, ...), the key of a bench.toml `[e2e.MESSAGE]` table is
the name itself (`Profile`, `DataID`, `MaxDeltaCounter`, ...). bench.toml overrides the database, which
overrides the defaults below (the contract's values, docs/spec/e2e.md "Parameters").
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from cantools.database.can import Message

from bench.e2e.profiles import P01_MODES, P11_MODES, PROFILES, Protection, SMConfig

#: DBC attribute prefix.
PREFIX = "E2E_"
#: "no protection" as a profile value.
NONE = "None"

#: The state machine's parameters by AUTOSAR name -> SMConfig field.
SM_PARAMETERS = {
    "WindowSize": "window_size",
    "MinOkStateInit": "min_ok_init", "MaxErrorStateInit": "max_error_init",
    "MinOkStateValid": "min_ok_valid", "MaxErrorStateValid": "max_error_valid",
    "MinOkStateInvalid": "min_ok_invalid", "MaxErrorStateInvalid": "max_error_invalid",
}
#: Every parameter by AUTOSAR name, with what it is (the DBC definitions, `bench dbc check`'s help, the docs).
PARAMETERS: dict[str, str] = {
    "Profile": "None, P01, P02, P05, P07 or P11",
    "DataID": "16-bit Data ID (P01, P05, P11); 32-bit (P07)",
    "DataIDMode": "how the Data ID enters the CRC: BOTH, ALT, LOW, NIBBLE (P01); BOTH, NIBBLE (P11)",
    "DataIDList": "P02: 16 Data IDs, one per counter value, as hex bytes '0A 0B ...'",
    "Offset": "bit of the E2E header's first bit (the CRC's), a multiple of 8 (P01, P05, P07, P11)",
    "DataLength": "bits covered by the CRC (0: the whole frame)",
    "MaxDeltaCounter": "largest counter step a receiver accepts (OKSOMELOST above 1)",
    "WindowSize": "statuses the state machine counts",
    "MinOkStateInit": "OK statuses in the window for INIT -> VALID",
    "MaxErrorStateInit": "ERROR statuses in the window above which INIT -> INVALID",
    "MinOkStateValid": "OK statuses in the window to stay VALID",
    "MaxErrorStateValid": "ERROR statuses in the window above which VALID -> INVALID",
    "MinOkStateInvalid": "OK statuses in the window for INVALID -> VALID",
    "MaxErrorStateInvalid": "ERROR statuses in the window allowed for INVALID -> VALID",
}

#: Defaults where a database gives no value: the contract's receiver (docs/spec/e2e.md "Parameters").
DEFAULT_MAX_DELTA_COUNTER = 2
DEFAULT_SM = SMConfig()


class ProtectionError(ValueError):
    """A message's E2E parameters that no profile can use; the text names the message and the parameter."""


@dataclass(frozen=True, slots=True)
class Declared:
    """A message's protection as declared, before it is checked: parameter name -> value, and where from."""

    values: dict[str, Any]
    source: str


def from_dbc(message: Message, definitions: Mapping[str, Any]) -> Declared | None:
    """The E2E attributes of a DBC message (its own values over the database's defaults, `definitions`: the
    database's attribute definitions), or None."""
    dbc = getattr(message, "dbc", None)
    if dbc is None:
        return None
    values: dict[str, Any] = {}
    for name in PARAMETERS:
        definition = definitions.get(PREFIX + name)
        if definition is not None and definition.default_value not in (None, ""):
            values[name] = _enum(definition, definition.default_value)
    for key, attribute in (dbc.attributes or {}).items():
        if key.startswith(PREFIX) and key[len(PREFIX):] in PARAMETERS:
            values[key[len(PREFIX):]] = _enum(attribute.definition, attribute.value)
    if str(values.get("Profile", NONE)) == NONE:
        return None
    return Declared(values, "DBC attributes")


def _enum(definition: Any, value: Any) -> Any:
    """An ENUM attribute's value by its name (cantools gives a message's value as the index)."""
    choices = getattr(definition, "choices", None)
    if choices and isinstance(value, int) and 0 <= value < len(choices):
        return choices[value]
    return value


def from_arxml(message: Message) -> Declared | None:
    """The E2E properties cantools reads from an ARXML message (`Message.autosar.e2e`), or None."""
    autosar = getattr(message, "autosar", None)
    e2e = getattr(autosar, "e2e", None)
    if e2e is None or not e2e.category:
        return None
    category = str(e2e.category).upper().replace("PROFILE_", "PROFILE")
    number = "".join(ch for ch in category if ch.isdigit())
    profile = f"P{int(number):02d}" if number else category
    values: dict[str, Any] = {"Profile": profile}
    ids = list(e2e.data_ids or [])
    if profile == "P02":
        values["DataIDList"] = bytes(ids)
    elif ids:
        values["DataID"] = ids[0]
    if e2e.payload_length:
        values["DataLength"] = 8 * int(e2e.payload_length)
    return Declared(values, "ARXML")


def declared(message: Message, definitions: Mapping[str, Any],
             override: Mapping[str, Any] | None = None) -> Declared | None:
    """What protects a message: bench.toml's `[e2e.NAME]` over the database's own declaration."""
    base = from_dbc(message, definitions) or from_arxml(message)
    if not override:
        return base
    values = dict(base.values) if base else {}
    values.update(override)
    if str(values.get("Profile", NONE)) == NONE:
        return None
    source = "bench.toml [e2e]" if base is None else f"{base.source}, bench.toml [e2e]"
    return Declared(values, source)


def protection(message: Message, definitions: Mapping[str, Any],
               override: Mapping[str, Any] | None = None) -> Protection | None:
    """The checked Protection of a message, or None when nothing protects it (`definitions`: its database's
    attribute definitions). A ProtectionError names the message and the parameter that no profile can use."""
    found = declared(message, definitions, override)
    if found is None:
        return None
    return build(message.name, message.length, found)


def build(name: str, frame_length: int, found: Declared) -> Protection:
    values = found.values
    unknown = sorted(set(values) - set(PARAMETERS))
    if unknown:
        raise ProtectionError(f"{name}: unknown E2E parameter {unknown[0]!r} (parameters: {', '.join(PARAMETERS)})")
    profile = str(values.get("Profile"))
    if profile not in PROFILES:
        raise ProtectionError(f"{name}: E2E profile {profile!r} is not supported (supported: {', '.join(PROFILES)})")

    def integer(key: str, default: int, lo: int, hi: int) -> int:
        raw = values.get(key, default)
        try:
            number = int(raw, 0) if isinstance(raw, str) else int(raw)
        except (TypeError, ValueError):
            raise ProtectionError(f"{name}: E2E {key} {raw!r} is not a whole number") from None
        if not lo <= number <= hi:
            raise ProtectionError(f"{name}: E2E {key} {number} is outside {lo}-{hi}")
        return number

    mode = str(values.get("DataIDMode", "BOTH"))
    modes = P01_MODES if profile == "P01" else P11_MODES if profile == "P11" else {"BOTH": 0}
    if mode not in modes:
        raise ProtectionError(f"{name}: E2E DataIDMode {mode!r} is not one of {', '.join(modes)} for {profile}")
    id_list = b""
    if profile == "P02":
        id_list = _id_list(name, values.get("DataIDList"))
    data_id = integer("DataID", 0, 0, 0xFFFFFFFF if profile == "P07" else 0xFFFF)
    offset = 0 if profile == "P02" else integer("Offset", 0, 0, 8 * frame_length)
    if offset % 8:
        raise ProtectionError(f"{name}: E2E Offset {offset} is not a multiple of 8")
    data_length = integer("DataLength", 0, 0, 8 * frame_length)
    if data_length % 8:
        raise ProtectionError(f"{name}: E2E DataLength {data_length} is not a multiple of 8")
    sm_values = {field_name: integer(key, getattr(DEFAULT_SM, field_name), 0, 255)
                 for key, field_name in SM_PARAMETERS.items()}
    sm = SMConfig(**sm_values)
    problems = sm.problems()
    if problems:
        raise ProtectionError(f"{name}: E2E state machine: {problems[0]}")
    result = Protection(profile, data_id=data_id, data_id_list=id_list, data_id_mode=mode, offset=offset,
                        length=data_length // 8,
                        max_delta_counter=integer("MaxDeltaCounter", DEFAULT_MAX_DELTA_COUNTER, 1, 255),
                        sm=sm, source=found.source)
    header_end = result.header_end
    covered = 8 * (result.length or frame_length)
    if header_end > 8 * frame_length or header_end > covered:
        raise ProtectionError(f"{name}: the {profile} header (bits {result.crc.start}-{header_end - 1}) does not fit "
                              f"the {frame_length}-byte frame's protected {covered // 8} bytes")
    if result.max_delta_counter >= result.counter_modulo:
        raise ProtectionError(f"{name}: E2E MaxDeltaCounter {result.max_delta_counter} must be below the counter's "
                              f"{result.counter_modulo} values")
    return result


def _id_list(name: str, raw: Any) -> bytes:
    if isinstance(raw, (bytes, bytearray)):
        ids = bytes(raw)
    else:
        try:
            ids = bytes(int(part, 16) for part in str(raw or "").replace(",", " ").split())
        except ValueError:
            raise ProtectionError(f"{name}: E2E DataIDList {raw!r} is not hex bytes like '0A 0B ...'") from None
    if len(ids) != 16:
        raise ProtectionError(f"{name}: E2E DataIDList has {len(ids)} Data IDs, P02 needs 16 (one per counter value)")
    return ids


def sm_parameters(sm: SMConfig) -> dict[str, int]:
    """The state machine's parameters by AUTOSAR name."""
    return {key: getattr(sm, field_name) for key, field_name in SM_PARAMETERS.items()}


