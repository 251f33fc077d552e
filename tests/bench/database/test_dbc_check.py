"""`bench dbc check`: each check fails on a database made to break it, with the line of the culprit;
our own databases pass (every message protected); every file of the cantools corpus, DBC and ARXML, is accepted
or rejected without a traceback.

The small databases below are written by hand; expected lines are found by searching the test's own
text for the statement that is wrong (never read back from the checker).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import cantools
import pytest

from bench.cli import main
from bench.database.check import ERROR, CheckResult, Finding, check_file, check_text
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

CORPUS = ROOT.parent / "shared" / "corpus" / "dbc"        # the CI keeps shared/ beside the repository's clone
ARXML_CORPUS = ROOT.parent / "shared" / "corpus" / "arxml"

HEADER = 'VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: ECU TESTER\n\n'
SIGNALS = (
    ' SG_ Speed : 0|16@1- (0.01,0) [-300|300] "m/s" TESTER\n'
    ' SG_ Mode : 16|4@1+ (1,0) [0|3] "-" TESTER\n'
    ' SG_ AliveCounter : 56|4@1+ (1,0) [0|14] "-" TESTER\n'
    ' SG_ Checksum : 48|8@1+ (1,0) [0|255] "-" TESTER\n'
)
#: Profile 11 as the contract declares it: the CRC in byte 6, the counter in the low nibble of byte 7.
E2E_DEFINITIONS = (
    'BA_DEF_ BO_  "E2E_Profile" ENUM  "None","P01","P02","P05","P11";\n'
    'BA_DEF_ BO_  "E2E_DataID" INT 0 65535;\n'
    'BA_DEF_ BO_  "E2E_DataIDList" STRING ;\n'
    'BA_DEF_ BO_  "E2E_Offset" INT 0 504;\n'
    'BA_DEF_ BO_  "E2E_WindowSize" INT 1 255;\n'
    'BA_DEF_ BO_  "E2E_MaxErrorStateValid" INT 0 255;\n'
    'BA_DEF_DEF_  "E2E_Profile" "None";\n'
    'BA_DEF_DEF_  "E2E_DataID" 0;\n'
    'BA_DEF_DEF_  "E2E_DataIDList" "";\n'
    'BA_DEF_DEF_  "E2E_Offset" 48;\n'
    'BA_DEF_DEF_  "E2E_WindowSize" 2;\n'
    'BA_DEF_DEF_  "E2E_MaxErrorStateValid" 0;\n'
)
E2E_VALUES = (
    'BA_ "E2E_Profile" BO_ 256 4;\n'
    'BA_ "E2E_DataID" BO_ 256 256;\n'
)
FOOTER = (
    'CM_ BO_ 256 "Status of the ECU.";\n'
    'CM_ SG_ 256 Speed "Speed.";\n'
    'CM_ SG_ 256 Mode "Mode.";\n'
    'CM_ SG_ 256 AliveCounter "Counter.";\n'
    'CM_ SG_ 256 Checksum "CRC-8.";\n'
    'BA_DEF_ BO_  "GenMsgCycleTime" INT 0 65535;\n'
    'BA_DEF_ BO_  "GenMsgSendType" ENUM  "Cyclic","NoMsgSendType";\n'
    'BA_DEF_ SG_  "GenSigStartValue" INT -2147483648 2147483647;\n'
    'BA_DEF_DEF_  "GenMsgCycleTime" 0;\n'
    'BA_DEF_DEF_  "GenMsgSendType" "NoMsgSendType";\n'
    'BA_DEF_DEF_  "GenSigStartValue" 0;\n'
    + E2E_DEFINITIONS +
    'BA_ "GenMsgCycleTime" BO_ 256 10;\n'
    'BA_ "GenMsgSendType" BO_ 256 0;\n'
    + E2E_VALUES +
    'BA_ "GenSigStartValue" SG_ 256 Speed 0;\n'
    'BA_ "GenSigStartValue" SG_ 256 Mode 0;\n'
    'BA_ "GenSigStartValue" SG_ 256 AliveCounter 0;\n'
    'BA_ "GenSigStartValue" SG_ 256 Checksum 0;\n'
    'VAL_ 256 Mode 0 "OFF" 1 "LOW" 2 "HIGH" 3 "AUTO" ;\n'
)
GOOD = HEADER + "BO_ 256 ECU_Status: 8 ECU\n" + SIGNALS + "\n" + FOOTER


def line_of(text: str, needle: str) -> int:
    """1-based line of the only line containing `needle`."""
    hits = [i for i, line in enumerate(text.split("\n"), 1) if needle in line]
    assert len(hits) == 1, (needle, hits)
    return hits[0]


def errors(result: CheckResult, kind: str) -> list[Finding]:
    return [f for f in result.errors if f.kind == kind]


def warnings(result: CheckResult, kind: str) -> list[Finding]:
    return [f for f in result.warnings if f.kind == kind]


def only(findings: list[Finding]) -> Finding:
    assert len(findings) == 1, findings
    return findings[0]


# -- the reference database and ours -----------------------------------------------------------------------
def test_good_database_has_no_finding() -> None:
    result = check_text(GOOD)
    assert result.findings == []
    assert result.accepted and result.messages == 1 and result.signals == 4 and result.e2e == "optional"
    assert (result.protected, result.unprotected) == (1, 0)
    protection = result.protections[0].protection
    assert protection is not None and (protection.profile, protection.data_id, protection.offset) == ("P11", 256, 48)


@pytest.mark.parametrize("path", [CHASSIS_DBC, BENCH_DBC], ids=lambda p: p.name)
def test_our_databases_pass(path: Path) -> None:
    """The contract protects every message: checked as CI checks it, with --e2e required."""
    result = check_file(path, e2e_mode="required", strict=True)
    assert result.errors == [], result.errors
    assert result.e2e == "required" and result.unprotected == 0
    assert result.protected + result.diagnostic == result.messages
    assert {p.protection.profile for p in result.protections if p.protection} == {"P11"}


# -- layout --------------------------------------------------------------------------------------------------
def test_overlap_little_endian() -> None:
    text = GOOD.replace(' SG_ Mode : 16|4@1+', ' SG_ Mode : 12|4@1+')
    result = check_text(text)
    finding = only(errors(result, "overlap"))
    assert (finding.message, finding.signal) == ("ECU_Status", "Mode")
    assert finding.line == line_of(text, " SG_ Mode ")
    assert "Speed" in finding.text and "12-15" in finding.text
    assert not result.accepted
    assert not errors(result, "load"), "cantools' strict message repeats our overlap finding"


def test_overlap_big_endian() -> None:
    # Motorola: start bit 7 (MSB of byte 0), 8 bits -> all of byte 0, which Speed (Intel, bits 0-15) also uses
    text = GOOD.replace(' SG_ Mode : 16|4@1+', ' SG_ Mode : 7|8@0+')
    finding = only(errors(check_text(text), "overlap"))
    assert finding.signal == "Mode" and "0-7" in finding.text


def test_big_endian_without_overlap_is_accepted() -> None:
    # Motorola 23|16: bits 23..16 (byte 2) then 31..24 (byte 3), clear of Speed (bytes 0-1) and E2E (bytes 6-7)
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 23|16@0+ (1,0) [0|3]')
    result = check_text(text)
    assert result.errors == []


def test_signal_does_not_fit_the_frame() -> None:
    # without the E2E signals (bytes 6-7 free): Intel 60|8 runs to bit 67, Motorola 63|16 on into byte 8
    plain = GOOD.replace(' SG_ AliveCounter : 56|4@1+ (1,0) [0|14] "-" TESTER\n', "").replace(
        ' SG_ Checksum : 48|8@1+ (1,0) [0|255] "-" TESTER\n', "")
    for layout in ("60|8@1+", "63|16@0+"):
        text = plain.replace(' SG_ Mode : 16|4@1+', f' SG_ Mode : {layout}')
        result = check_text(text)
        finding = only(errors(result, "fit"))
        assert finding.signal == "Mode" and finding.line == line_of(text, " SG_ Mode ")
        assert {f.kind for f in result.errors} == {"fit"}


def test_frame_length_and_extended_id() -> None:
    text = GOOD.replace("BO_ 256 ECU_Status: 8 ECU", "BO_ 2147483904 ECU_Status: 6 ECU")
    text = text.replace(" 256 ", " 2147483904 ")
    result = check_text(text)
    line = line_of(text, "BO_ 2147483904 ECU_Status")
    assert only(warnings(result, "frame-length")).line == line   # the contract's 8 bytes; the bench copes
    assert not errors(result, "frame-id")                        # a 29-bit identifier is one the bench sends
    assert errors(result, "fit")  # the E2E signals no longer fit in 6 bytes
    assert "does not fit" in only(errors(result, "e2e")).text    # nor does the declared P11 header
    longer = check_text(GOOD.replace("BO_ 256 ECU_Status: 8 ECU", "BO_ 256 ECU_Status: 12 ECU"))
    assert "classical CAN" in only(errors(longer, "frame-length")).text
    fd = GOOD.replace("BO_ 256 ECU_Status: 8 ECU", "BO_ 256 ECU_Status: 10 ECU") + \
        'BA_DEF_ BO_ "VFrameFormat" ENUM "StandardCAN","ExtendedCAN","reserved","reserved","reserved","reserved",' \
        '"reserved","reserved","reserved","reserved","reserved","reserved","reserved","reserved","StandardCAN_FD",' \
        '"ExtendedCAN_FD";\nBA_ "VFrameFormat" BO_ 256 14;\n'
    odd = check_text(fd)                                          # CAN FD: 10 bytes is no DLC length, 12 goes out
    assert not errors(odd, "frame-length") and "as 12 bytes" in only(warnings(odd, "frame-length")).text


def test_multiplexed_message_is_accepted() -> None:
    text = GOOD.replace(' SG_ Mode : 16|4@1+', ' SG_ Mode M : 16|4@1+').replace(
        ' SG_ Speed : 0|16@1-', ' SG_ Speed m1 : 0|16@1-')
    result = check_text(text)     # the restbus sends each multiplexer value's frame in turn (tests/bench/sim)
    assert result.accepted and not errors(result, "multiplex")


def test_duplicate_identifier() -> None:
    second = ('BO_ 256 ECU_Other: 8 ECU\n SG_ X : 0|8@1+ (1,0) [0|1] "-" TESTER\n\n')
    text = GOOD.replace("\nCM_ BO_ 256", "\n" + second + "CM_ BO_ 256", 1)
    finding = only(errors(check_text(text), "duplicate-id"))
    assert finding.message == "ECU_Other" and finding.line == line_of(text, "ECU_Other")


# -- timing --------------------------------------------------------------------------------------------------
def test_missing_cycle_time_falls_back_to_default_zero() -> None:
    text = GOOD.replace('BA_ "GenMsgCycleTime" BO_ 256 10;\n', "")
    finding = only(errors(check_text(text), "cycle-time"))
    assert "default" in finding.text and finding.line == line_of(text, "BO_ 256 ECU_Status")


def test_missing_cycle_time_definition() -> None:
    text = GOOD.replace('BA_ "GenMsgCycleTime" BO_ 256 10;\n', "").replace(
        'BA_DEF_ BO_  "GenMsgCycleTime" INT 0 65535;\n', "").replace('BA_DEF_DEF_  "GenMsgCycleTime" 0;\n', "")
    assert "no GenMsgCycleTime" in only(errors(check_text(text), "cycle-time")).text


def test_zero_cycle_time_points_at_its_attribute() -> None:
    text = GOOD.replace('BA_ "GenMsgCycleTime" BO_ 256 10;', 'BA_ "GenMsgCycleTime" BO_ 256 0;')
    finding = only(errors(check_text(text), "cycle-time"))
    assert finding.line == line_of(text, '"GenMsgCycleTime" BO_ 256')


NO_SEND_TYPE = GOOD.replace('BA_ "GenMsgSendType" BO_ 256 0;\n', "").replace(
    'BA_DEF_ BO_  "GenMsgSendType" ENUM  "Cyclic","NoMsgSendType";\n', "").replace(
    'BA_DEF_DEF_  "GenMsgSendType" "NoMsgSendType";\n', "")


def test_send_type_missing_event_and_unknown() -> None:
    """No send type at all: the bench's default (cyclic, it has a cycle time), a warning naming the key; an event
    send type needs no cycle time; a send type the bench does not know is an error naming the key."""
    missing = only(warnings(check_text(NO_SEND_TYPE), "send-type"))
    assert "no GenMsgSendType: cyclic" in missing.text and 'send_type = "cyclic"' in missing.text
    event = GOOD.replace('BA_ "GenMsgSendType" BO_ 256 0;', 'BA_ "GenMsgSendType" BO_ 256 1;').replace(
        'BA_ "GenMsgCycleTime" BO_ 256 10;\n', "")
    result = check_text(event)        # NoMsgSendType: sent when written (on_write), no cycle time needed
    assert result.accepted and not errors(result, "send-type") and not errors(result, "cycle-time")
    unknown = GOOD.replace('"Cyclic","NoMsgSendType"', '"Cyclic","NotUsed"').replace(
        'BA_ "GenMsgSendType" BO_ 256 0;', 'BA_ "GenMsgSendType" BO_ 256 1;')
    finding = only(errors(check_text(unknown), "send-type"))
    assert "'NotUsed' is no send type the bench knows" in finding.text and 'send_type = "cyclic"' in finding.text
    assert finding.line == line_of(unknown, '"GenMsgSendType" BO_ 256')


def test_timing_errors_name_the_bench_toml_key_that_fixes_them() -> None:
    """An OEM's database is not the engineer's to edit: each timing error says which bench.toml key supplies
    what is missing, and with that key given the error is gone (bench.database.overrides)."""
    no_cycle = GOOD.replace('BA_ "GenMsgCycleTime" BO_ 256 10;\n', "")
    assert "bench.toml [messages.ECU_Status] cycle_time_ms = <ms>" in only(errors(check_text(no_cycle),
                                                                                  "cycle-time")).text
    assert check_text(no_cycle, message_overrides={"ECU_Status": {"cycle_time_ms": 10}}).accepted
    unknown = GOOD.replace('"Cyclic","NoMsgSendType"', '"Cyclic","NotUsed"').replace(
        'BA_ "GenMsgSendType" BO_ 256 0;', 'BA_ "GenMsgSendType" BO_ 256 1;')
    assert 'bench.toml [messages.ECU_Status] send_type = "cyclic"' in only(errors(check_text(unknown),
                                                                                  "send-type")).text
    assert check_text(unknown, message_overrides={"ECU_Status": {"send_type": "cyclic"}}).accepted


def test_a_projects_messages_table_reaches_dbc_check(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`bench dbc check` of a project checks its databases with its [messages] table; a name no database has is
    an error with the name meant."""
    dbc = tmp_path / "oem.dbc"
    dbc.write_text(GOOD.replace('BA_ "GenMsgCycleTime" BO_ 256 10;\n', ""))
    project = ('[bench]\ndatabases = ["oem.dbc"]\nstimulus = ["TESTER"]\nplant = "chassis"\ntestcases = "t"\n'
               'reports = "r"\n')
    (tmp_path / "bench.toml").write_text(project)
    assert main(["dbc", "check", "--config", str(tmp_path / "bench.toml")]) == 1
    assert "error [cycle-time]" in capsys.readouterr().out
    (tmp_path / "bench.toml").write_text(project + "[messages.ECU_Status]\ncycle_time_ms = 10\n")
    assert main(["dbc", "check", "--config", str(tmp_path / "bench.toml")]) == 0
    (tmp_path / "bench.toml").write_text(project + "[messages.ECU_Statu]\ncycle_time_ms = 10\n")
    assert main(["dbc", "check", "--config", str(tmp_path / "bench.toml")]) == 1
    out = " ".join(capsys.readouterr().out.split())
    assert "[messages.ECU_Statu]: no such message in the databases (did you mean ECU_Status?)" in out, out


# -- ranges, scale, start values -----------------------------------------------------------------------------
def test_range_wider_than_the_raw_field() -> None:
    """An error in a contract (--strict); in an OEM's database a warning saying what the bench judges instead."""
    # 16-bit signed at 0.01: -327.68..327.67, so +-400 cannot be carried
    text = GOOD.replace('(0.01,0) [-300|300]', '(0.01,0) [-400|400]')
    finding = only(errors(check_text(text, strict=True), "range-raw"))
    assert finding.signal == "Speed" and "-327.68" in finding.text and "327.67" in finding.text
    result = check_text(text)
    assert result.accepted and "the bench judges and accepts [-327.68|327.67]" in only(warnings(result,
                                                                                              "range-raw")).text


def test_range_at_the_raw_limits_is_accepted() -> None:
    text = GOOD.replace('(0.01,0) [-300|300]', '(0.01,0) [-327.68|327.67]')
    assert check_text(text).errors == []


def test_negative_scale_range() -> None:
    # unsigned 4 bits at scale -1, offset 0 carry -15..0; a range of 0..3 is not carried
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|4@1+ (-1,0) [-15|0]')
    assert not errors(check_text(text, strict=True), "range-raw")
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|4@1+ (-1,0) [0|3]')
    assert only(errors(check_text(text, strict=True), "range-raw")).signal == "Mode"


def test_range_minimum_above_maximum() -> None:
    text = GOOD.replace('[-300|300]', '[300|-300]')
    assert only(errors(check_text(text), "range-order")).signal == "Speed"


def test_scale_zero() -> None:
    text = GOOD.replace('(0.01,0) [-300|300]', '(0,0) [-300|300]')
    assert only(errors(check_text(text), "scale")).signal == "Speed"


def test_no_range_and_narrow_range_are_warnings() -> None:
    result = check_text(GOOD.replace('(0.01,0) [-300|300]', '(0.01,0) [0|0]'))
    assert only(warnings(result, "range")).signal == "Speed" and result.accepted
    result = check_text(GOOD.replace('(0.01,0) [-300|300]', '(0.01,0) [0|0.005]'))
    assert only(warnings(result, "resolution")).signal == "Speed" and result.accepted


def test_start_value_outside_the_range() -> None:
    text = GOOD.replace('BA_ "GenSigStartValue" SG_ 256 Speed 0;', 'BA_ "GenSigStartValue" SG_ 256 Speed 31000;')
    finding = only(errors(check_text(text, strict=True), "start-value"))
    assert finding.signal == "Speed" and "310" in finding.text
    assert finding.line == line_of(text, "SG_ 256 Speed 31000")
    result = check_text(text)      # an OEM's database: the restbus starts at the range's end (codec.start_values)
    assert result.accepted and "the restbus starts it at 300" in only(warnings(result, "start-value")).text


def test_start_value_outside_the_raw_field() -> None:
    text = GOOD.replace('BA_ "GenSigStartValue" SG_ 256 Mode 0;', 'BA_ "GenSigStartValue" SG_ 256 Mode 16;')
    finding = only(errors(check_text(text, strict=True), "start-value"))
    assert finding.signal == "Mode" and "4-bit" in finding.text
    assert "the restbus starts it at 3" in only(warnings(check_text(text), "start-value")).text
    no_range = text.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|4@1+ (1,0) [0|0]')
    assert "4-bit" in only(errors(check_text(no_range), "start-value")).text   # nothing to fall back to


def test_missing_start_value_uses_raw_zero() -> None:
    # no GenSigStartValue: the bench starts at raw 0, i.e. the offset; -40 lies outside [0|100]
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|8@1+ (1,-40) [0|100]').replace(
        'BA_ "GenSigStartValue" SG_ 256 Mode 0;\n', "").replace(
        'VAL_ 256 Mode 0 "OFF" 1 "LOW" 2 "HIGH" 3 "AUTO" ;\n', "")
    result = check_text(text, strict=True)
    assert only(warnings(result, "start-value")).signal == "Mode"
    finding = only(errors(result, "start-value"))
    assert "raw 0" in finding.text and "-40" in finding.text
    assert any("the restbus starts it at 0" in f.text for f in warnings(check_text(text), "start-value"))


# -- end-to-end protection, as declared -----------------------------------------------------------------------
def plain(text: str = GOOD) -> str:
    """The database without its E2E values (the definitions stay): every message unprotected."""
    return text.replace(E2E_VALUES, "")


def test_e2e_unprotected_is_fine_unless_required() -> None:
    result = check_text(plain())
    assert result.findings == [] and (result.protected, result.unprotected) == (0, 1)
    assert result.protections[0].describe() == "unprotected"
    required = check_text(plain(), e2e_mode="required")
    finding = only(errors(required, "e2e"))
    assert finding.line == line_of(GOOD, "BO_ 256 ECU_Status") and "--e2e required" in finding.text
    assert check_text(plain(GOOD.replace(E2E_DEFINITIONS, ""))).findings == []   # no E2E attributes at all


def test_e2e_signal_beside_its_field_is_a_warning() -> None:
    text = GOOD.replace(" SG_ AliveCounter : 56|4@1+", " SG_ AliveCounter : 57|4@1+")
    result = check_text(text)
    finding = only(warnings(result, "e2e"))
    assert (finding.signal, finding.line) == ("AliveCounter", line_of(text, " SG_ AliveCounter "))
    assert "overlaps the P11 counter field (bits 56-59)" in finding.text and "is 4 bits at bit 57" in finding.text
    assert result.accepted


def test_e2e_signal_on_its_field_but_signed_big_endian_scaled() -> None:
    # Motorola 55|8: bits 55..48, exactly the CRC's bits, but not the CRC as the profile writes it
    text = GOOD.replace(" SG_ Checksum : 48|8@1+ (1,0)", " SG_ Checksum : 55|8@0- (2,0)")
    finding = only(warnings(check_text(text), "e2e"))
    assert finding.signal == "Checksum"
    assert all(words in finding.text for words in ("big-endian", "signed", "scale 2", "CRC field"))


def test_e2e_field_over_another_signal() -> None:
    text = GOOD.replace(' SG_ Mode : 16|4@1+', ' SG_ Mode : 58|4@1+')   # bits 58-61: half on the counter
    finding = only(warnings(check_text(text), "e2e"))
    assert finding.signal == "Mode" and "counter field (bits 56-59)" in finding.text


@pytest.mark.parametrize("old, new, words", [
    ('"None","P01","P02","P05","P11";', '"None","P01","P02","P05","P11","P22";', "'P22' is not supported"),
    ('BA_ "E2E_Profile" BO_ 256 4;', 'BA_ "E2E_Profile" BO_ 256 2;\nBA_ "E2E_DataIDList" BO_ 256 "01 02";',
     "DataIDList has 2 Data IDs, P02 needs 16"),
    ('BA_ "E2E_DataID" BO_ 256 256;', 'BA_ "E2E_DataID" BO_ 256 256;\nBA_ "E2E_Offset" BO_ 256 56;',
     "does not fit"),
    ('BA_ "E2E_DataID" BO_ 256 256;', 'BA_ "E2E_DataID" BO_ 256 256;\nBA_ "E2E_MaxErrorStateValid" BO_ 256 1;',
     "MinOkStateValid 2 + MaxErrorStateValid 1 exceed WindowSize 2"),
], ids=["profile", "data-id-list", "header-outside", "sm-window"])
def test_e2e_declaration_no_profile_can_use(old: str, new: str, words: str) -> None:
    text = GOOD.replace(old, new)
    if "P22" in new:
        text = text.replace('BA_ "E2E_Profile" BO_ 256 4;', 'BA_ "E2E_Profile" BO_ 256 5;')
    result = check_text(text)
    finding = only(errors(result, "e2e"))
    assert (finding.message, finding.line) == ("ECU_Status", line_of(text, "BO_ 256 ECU_Status"))
    assert words in finding.text and not finding.text.startswith("ECU_Status"), finding.text
    assert result.protections[0].refused and (result.protected, result.unprotected) == (0, 0)


def test_e2e_choice_the_bench_does_not_know_is_a_warning_on_its_definition() -> None:
    text = GOOD.replace('"None","P01","P02","P05","P11";', '"None","P01","P02","P05","P11","P22";')
    finding = only(warnings(check_text(text), "e2e-attribute"))
    assert finding.line == line_of(text, 'BA_DEF_ BO_  "E2E_Profile"') and "'P22'" in finding.text


def test_e2e_attribute_set_but_not_defined() -> None:
    """cantools refuses the file (a bare KeyError); the finding says which attribute and where it is set."""
    text = GOOD.replace('BA_DEF_ BO_  "E2E_Profile" ENUM  "None","P01","P02","P05","P11";\n', "").replace(
        'BA_DEF_DEF_  "E2E_Profile" "None";\n', "")
    finding = only(check_text(text).findings)
    assert (finding.severity, finding.kind) == (ERROR, "attribute")
    assert finding.line == line_of(text, 'BA_ "E2E_Profile"') and "E2E_Profile is set but never defined" in finding.text


def test_e2e_attribute_the_bench_does_not_know() -> None:
    text = GOOD.replace('BA_DEF_ BO_  "E2E_DataID" INT 0 65535;\n',
                        'BA_DEF_ BO_  "E2E_DataID" INT 0 65535;\nBA_DEF_ BO_  "E2E_MaxDeltaCountr" INT 0 255;\n')
    finding = only(warnings(check_text(text), "e2e-attribute"))
    assert finding.line == line_of(text, '"E2E_MaxDeltaCountr"')
    assert "did you mean E2E_MaxDeltaCounter?" in finding.text and "ignored" in finding.text


def test_e2e_attribute_on_a_signal_is_a_warning() -> None:
    text = GOOD.replace('BA_DEF_ BO_  "E2E_WindowSize" INT 1 255;', 'BA_DEF_ SG_  "E2E_WindowSize" INT 1 255;')
    text = text.replace('BA_ "GenSigStartValue" SG_ 256 Mode 0;\n',
                        'BA_ "GenSigStartValue" SG_ 256 Mode 0;\nBA_ "E2E_WindowSize" SG_ 256 Mode 3;\n')
    found = warnings(check_text(text), "e2e-attribute")
    assert [f.line for f in found] == [line_of(text, '"E2E_WindowSize" INT'), line_of(text, '"E2E_WindowSize" SG_ 256')]


def test_e2e_override_over_the_database() -> None:
    result = check_text(plain(), e2e_overrides={"ECU_Status": {"Profile": "P11", "DataID": 0x100, "Offset": 48}})
    protection = result.protections[0].protection
    assert result.findings == [] and protection is not None and protection.source == "bench.toml [e2e]"
    refused = only(errors(check_text(GOOD, e2e_overrides={"ECU_Status": {"WindowSize": 1}}), "e2e"))
    assert "exceed WindowSize 1" in refused.text and "(bench.toml [e2e] applied)" in refused.text


# -- value tables, units, comments ---------------------------------------------------------------------------
def test_value_tables() -> None:
    empty = GOOD.replace('VAL_ 256 Mode 0 "OFF" 1 "LOW" 2 "HIGH" 3 "AUTO" ;', 'VAL_ 256 Mode ;')
    finding = only(warnings(check_text(empty), "value-table"))
    assert "empty" in finding.text and finding.line == line_of(empty, "VAL_ 256 Mode")
    twice = GOOD.replace('2 "HIGH" 3 "AUTO"', '2 "HIGH" 3 "HIGH"')
    assert "HIGH" in only(warnings(check_text(twice), "value-table")).text
    outside = GOOD.replace('3 "AUTO"', '3 "AUTO" 16 "BEYOND"')
    assert "16" in only(warnings(check_text(outside), "value-table")).text
    repeated = GOOD.replace('3 "AUTO"', '3 "AUTO" 3 "AGAIN"')
    assert "named twice" in only(warnings(check_text(repeated), "value-table")).text


def test_unit_and_comments_are_warnings() -> None:
    text = GOOD.replace('[-300|300] "m/s"', '[-300|300] ""').replace('CM_ SG_ 256 Speed "Speed.";\n', "").replace(
        'CM_ BO_ 256 "Status of the ECU.";\n', "")
    result = check_text(text)
    assert result.accepted
    assert only(warnings(result, "unit")).signal == "Speed"
    assert {(f.message, f.signal) for f in warnings(result, "comment")} == {("ECU_Status", None),
                                                                             ("ECU_Status", "Speed")}


# -- files that do not load ----------------------------------------------------------------------------------
def test_syntax_error_has_its_line() -> None:
    text = GOOD.replace(" SG_ Mode : 16|4@1+", " SG_ Mode 16|4@1+")
    result = check_text(text)
    finding = only(result.findings)
    assert (finding.severity, finding.kind) == (ERROR, "syntax")
    assert finding.line == line_of(text, " SG_ Mode ")


def test_frame_id_too_large_has_its_line() -> None:
    text = GOOD.replace("BO_ 256 ECU_Status", "BO_ 4096 ECU_Status")
    finding = only(check_text(text).findings)
    assert finding.severity == ERROR and finding.line == line_of(text, "BO_ 4096")


@pytest.mark.parametrize("old, new, kind", [
    ("BO_ 256 ECU_Status: 8 ECU", "BO_ 256 ECU_Status: 99999999 ECU", "frame-length"),
    (" SG_ Mode : 16|4@1+", " SG_ Mode : 99999999|4@1+", "fit"),
    (" SG_ Mode : 16|4@1+", " SG_ Mode : 16|99999999@1+", "fit"),
], ids=["dlc", "start", "length"])
def test_absurd_numbers_are_reported_without_loading(old: str, new: str, kind: str) -> None:
    """cantools takes minutes (quadratic in the start bit) or all memory on these; the checker answers at once."""
    text = GOOD.replace(old, new)
    finding = only(check_text(text).findings)
    assert (finding.severity, finding.kind, finding.line) == (ERROR, kind, line_of(text, "99999999"))


@pytest.mark.parametrize("eol", ["\n", "\r\n"], ids=["lf", "crlf"])
def test_odd_whitespace_and_cp1252(tmp_path: Path, eol: str) -> None:
    """Tabs and runs of blanks in BO_/SG_ lines, CRLF, and a cp1252 degree sign in a unit."""
    text = GOOD.replace("BO_ 256 ECU_Status:", "BO_\t256   ECU_Status :").replace(
        " SG_ Mode : 16|4@1+ (1,0) [0|3] \"-\"", "\t SG_   Mode\t: 16|4@1+ (1,0) [0|3] \"°C\"")
    text = text.replace(' SG_ Speed : 0|16@1- (0.01,0) [-300|300]', ' SG_ Speed : 0|16@1- (0.01,0) [-300|301]')
    text = text.replace(" SG_ AliveCounter : 56|4@1+", " SG_ AliveCounter : 57|4@1+")
    path = tmp_path / "odd.dbc"
    path.write_bytes(text.replace("\n", eol).encode("cp1252"))
    result = check_file(path)
    assert result.encoding == "cp1252"
    assert only(warnings(result, "e2e")).line == line_of(text, "SG_ AliveCounter")
    assert result.errors == [] and {f.kind for f in result.warnings} == {"e2e"}
    assert result.messages == 1 and result.signals == 4


def test_utf8_file(tmp_path: Path) -> None:
    path = tmp_path / "utf8.dbc"
    path.write_text(GOOD.replace('"Speed."', '"Geschwindigkeit über Grund."'), encoding="utf-8")
    result = check_file(path)
    assert result.encoding == "utf-8" and result.findings == []


# -- the command ---------------------------------------------------------------------------------------------
def test_cli_good_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "good.dbc"
    path.write_text(GOOD)
    assert main(["dbc", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{path}: accepted: 0 errors, 0 warnings (1 messages: 1 protected, 0 unprotected;" in out
    assert (f"{path}: ECU_Status 0x100: P11 DataID 0x0100 BOTH, CRC bits 48-55, counter bits 56-59 (0-14), "
            "MaxDeltaCounter 2, window 2 (init 1/0, valid 2/0, invalid 2/0) [DBC attributes]") in out


def test_cli_warnings_only_pass(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "warn.dbc"
    path.write_text(GOOD.replace('[-300|300] "m/s"', '[-300|300] ""'))
    assert main(["dbc", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{path}:{line_of(GOOD, ' SG_ Speed ')}: warning [unit] ECU_Status.Speed: no unit" in out


def test_cli_errors_fail_with_file_and_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "overlap.dbc"
    text = GOOD.replace(' SG_ Mode : 16|4@1+', ' SG_ Mode : 12|4@1+')
    path.write_text(text)
    assert main(["dbc", "check", str(path)]) == 1
    out = capsys.readouterr().out
    assert f"{path}:{line_of(text, ' SG_ Mode ')}: error [overlap] ECU_Status.Mode:" in out
    assert f"{path}: rejected: 1 error" in out


def test_cli_syntax_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "broken.dbc"
    path.write_text('VERSION ""\nBU_: A\nBO_ 1 X: 8 A\n SG_ S 0|8@1+ (1,0) [0|1] "" A\n')
    assert main(["dbc", "check", str(path)]) == 1
    captured = capsys.readouterr()
    assert f"{path}:4: error [syntax]" in captured.out
    assert "Traceback" not in captured.out + captured.err


def test_cli_unreadable_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "good.dbc"
    good.write_text(GOOD)
    assert main(["dbc", "check", str(tmp_path / "nowhere.dbc"), str(good), str(tmp_path)]) == 2
    captured = capsys.readouterr()
    err = captured.err.replace("\n", "")
    assert "nowhere.dbc: cannot read" in err and "is a folder" in err
    assert f"{good}: accepted" in captured.out           # the readable one is still checked
    assert "3 files: 1 accepted, 0 rejected, 2 unreadable" in captured.out


def test_cli_default_checks_our_databases(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dbc", "check", "--e2e", "required", "--strict"]) == 0     # the contract protects every message
    out = capsys.readouterr().out
    assert f"{CHASSIS_DBC}: accepted" in out and f"{BENCH_DBC}: accepted" in out
    assert "0 unprotected; " in out and "unprotected\n" not in out


def test_cli_e2e_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "plain.dbc"
    path.write_text(plain())
    assert main(["dbc", "check", str(path)]) == 0
    assert f"{path}: ECU_Status 0x100: unprotected" in capsys.readouterr().out
    assert main(["dbc", "check", "--e2e", "required", str(path)]) == 1
    assert "error [e2e] ECU_Status: no E2E protection declared" in capsys.readouterr().out
    assert main(["dbc", "--e2e", "required"]) == 2      # the option belongs to check
    assert "only for 'bench dbc check" in capsys.readouterr().err.replace("\n", "")
    assert main(["dbc", "check", "--e2e", "auto", str(path)]) == 2   # the old mode is gone, said in one line
    assert "invalid choice: 'auto'" in capsys.readouterr().err


def test_cli_help_says_what_e2e_means(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["dbc", "check", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "optional (the default)" in text and "required: every message must declare a profile" in text


def test_listing_a_file_named_check(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("COLUMNS", "200")
    (tmp_path / "check").write_text(GOOD)
    monkeypatch.chdir(tmp_path)
    assert main(["dbc", "./check"]) == 0
    assert "ECU_Status" in capsys.readouterr().out


# -- the cantools corpus -------------------------------------------------------------------------------------
CORPUS_FILES = sorted(p for p in CORPUS.iterdir() if p.is_file()) if CORPUS.is_dir() else []

# Known outcomes, from reading these files: each is rejected for the reason named.
KNOWN_REJECTIONS = {
    "LICENSE-cantools": "syntax",             # not a DBC at all
    "bad_message_length.dbc": "fit",          # Signal1 at bit 8 of a 1-byte message
    "issue_63.dbc": "overlap",                # HtrRes and MaxRes share byte 5
    "issue_199.dbc": "load",                  # a standard id wider than 11 bits: cantools refuses the file
}


@pytest.mark.skipif(not CORPUS_FILES, reason=f"no corpus at {CORPUS}")
@pytest.mark.parametrize("path", CORPUS_FILES, ids=lambda p: p.name)
def test_corpus_file_is_accepted_or_rejected_cleanly(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["dbc", "check", str(path)])
    captured = capsys.readouterr()
    output = captured.out + captured.err
    assert "Traceback" not in output
    assert code in (0, 1), output
    verdict = "accepted" if code == 0 else "rejected"
    assert f"{path}: {verdict}:" in captured.out
    if code == 1:   # a rejection names at least one error with its line
        assert any(line.startswith(f"{path}:") and ": error [" in line and line[len(str(path)) + 1].isdigit()
                   for line in captured.out.splitlines()), captured.out
    if path.name in KNOWN_REJECTIONS:
        assert code == 1 and f"error [{KNOWN_REJECTIONS[path.name]}]" in captured.out, captured.out


@pytest.mark.skipif(not CORPUS_FILES, reason=f"no corpus at {CORPUS}")
def test_corpus_accepts_a_file_only_when_each_message_can_be_sent() -> None:
    """An accepted file's periodic messages (Vector's Cyclic or IfActive, or no send type with a cycle time) each
    have a positive cycle time, counted here from cantools' reading, not from the check's."""
    results = [check_file(p) for p in CORPUS_FILES]
    accepted = [r.path for r in results if r.accepted]
    assert accepted and all(r.findings for r in results)
    for path in accepted:
        for message in cantools.database.load_file(str(path), strict=False).messages:
            declared = str(message.send_type or "").lower()
            periodic = "cyclic" in declared or "ifactive" in declared or (not declared and message.cycle_time)
            if periodic and not message.is_multiplexed():
                assert message.cycle_time and message.cycle_time > 0, (path.name, message.name)


# -- the ARXML corpus: no line numbers, findings name the message --------------------------------------------
ARXML_FILES = sorted(ARXML_CORPUS.glob("*.arxml")) if ARXML_CORPUS.is_dir() else []


@pytest.mark.skipif(not ARXML_FILES, reason=f"no ARXML corpus at {ARXML_CORPUS}")
@pytest.mark.parametrize("path", ARXML_FILES, ids=lambda p: p.name)
def test_arxml_file_is_accepted_or_rejected_cleanly(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["dbc", "check", str(path)])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    assert code in (0, 1) and f"{path}: {'accepted' if code == 0 else 'rejected'}:" in captured.out
    assert not any(line.startswith(f"{path}:") and line[len(str(path)) + 1:][:1].isdigit()
                   for line in captured.out.splitlines())    # no line numbers in ARXML


@pytest.mark.skipif(not (ARXML_CORPUS / "system-4.2.arxml").is_file(), reason=f"no ARXML corpus at {ARXML_CORPUS}")
def test_arxml_findings_name_the_message() -> None:
    result = check_file(ARXML_CORPUS / "system-4.2.arxml")
    by_name = {p.name: p.protection for p in result.protections}
    assert by_name["Message1"] is not None and by_name["Message1"].profile == "P02"
    assert by_name["Message3"] is not None and by_name["Message3"].profile == "P05"
    assert (result.protected, result.unprotected) == (2, 6)
    assert all(f.line is None and f.message for f in result.findings)
    assert not errors(result, "e2e")
    overlap = [f for f in warnings(result, "e2e") if f.message == "Message1"]
    assert overlap and all(f.signal == "message1_SeqCounter" for f in overlap)


def test_listing_into_a_pipe_is_whole() -> None:
    """Issue 34, the front door: `bench dbc | less` cut the table at 80 columns (`0…`, `DR…`). Into a pipe every
    identifier, name, sender and cycle time is whole, and nothing is cut."""
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    out = subprocess.run([sys.executable, "-m", "bench", "dbc"], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, env=env).stdout
    assert "…" not in out
    rows = {line.split("│")[2].strip(): line for line in out.splitlines() if line.count("│") > 3
            and line.split("│")[2].strip()}
    database = cantools.database.load_file(str(CHASSIS_DBC))
    for message in database.messages:
        row = rows.get(message.name)
        assert row is not None, message.name
        assert f"0x{message.frame_id:03X}" in row and ", ".join(message.senders) in row
