"""`bench dbc check`: each check fails on a database made to break it, with the line of the culprit;
our own databases pass; every file of the cantools corpus is accepted or rejected without a traceback.

The small databases below are written by hand; expected lines are found by searching the test's own
text for the statement that is wrong (never read back from the checker).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.cli import main
from bench.dbccheck import ERROR, CheckResult, Finding, check_file, check_text
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

CORPUS = ROOT.parent / "shared" / "corpus" / "dbc"

HEADER = 'VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_: ECU TESTER\n\n'
SIGNALS = (
    ' SG_ Speed : 0|16@1- (0.01,0) [-300|300] "m/s" TESTER\n'
    ' SG_ Mode : 16|4@1+ (1,0) [0|3] "-" TESTER\n'
    ' SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "-" TESTER\n'
    ' SG_ Checksum : 56|8@1+ (1,0) [0|255] "-" TESTER\n'
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
    'BA_ "GenMsgCycleTime" BO_ 256 10;\n'
    'BA_ "GenMsgSendType" BO_ 256 0;\n'
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
    assert result.accepted and result.messages == 1 and result.signals == 4 and result.e2e == "required"


@pytest.mark.parametrize("path", [CHASSIS_DBC, BENCH_DBC], ids=lambda p: p.name)
def test_our_databases_pass(path: Path) -> None:
    result = check_file(path)
    assert result.errors == [], result.errors
    assert result.e2e == "required"


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
    plain = GOOD.replace(' SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "-" TESTER\n', "").replace(
        ' SG_ Checksum : 56|8@1+ (1,0) [0|255] "-" TESTER\n', "")
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
    assert only(errors(result, "frame-length")).line == line
    assert only(errors(result, "frame-id")).line == line
    assert errors(result, "fit")  # the E2E signals no longer fit in 6 bytes


def test_multiplexed_message_is_rejected() -> None:
    text = GOOD.replace(' SG_ Mode : 16|4@1+', ' SG_ Mode M : 16|4@1+').replace(
        ' SG_ Speed : 0|16@1-', ' SG_ Speed m1 : 0|16@1-')
    assert only(errors(check_text(text), "multiplex")).message == "ECU_Status"


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


def test_send_type_missing_and_not_cyclic() -> None:
    missing = GOOD.replace('BA_ "GenMsgSendType" BO_ 256 0;\n', "").replace(
        'BA_DEF_ BO_  "GenMsgSendType" ENUM  "Cyclic","NoMsgSendType";\n', "").replace(
        'BA_DEF_DEF_  "GenMsgSendType" "NoMsgSendType";\n', "")
    assert only(errors(check_text(missing), "send-type"))
    event = GOOD.replace('BA_ "GenMsgSendType" BO_ 256 0;', 'BA_ "GenMsgSendType" BO_ 256 1;')
    result = check_text(event)
    finding = only(warnings(result, "send-type"))
    assert "NoMsgSendType" in finding.text and finding.line == line_of(event, '"GenMsgSendType" BO_ 256')
    assert result.accepted


# -- ranges, scale, start values -----------------------------------------------------------------------------
def test_range_wider_than_the_raw_field() -> None:
    # 16-bit signed at 0.01: -327.68..327.67, so +-400 cannot be carried
    text = GOOD.replace('(0.01,0) [-300|300]', '(0.01,0) [-400|400]')
    finding = only(errors(check_text(text), "range-raw"))
    assert finding.signal == "Speed" and "-327.68" in finding.text and "327.67" in finding.text


def test_range_at_the_raw_limits_is_accepted() -> None:
    text = GOOD.replace('(0.01,0) [-300|300]', '(0.01,0) [-327.68|327.67]')
    assert check_text(text).errors == []


def test_negative_scale_range() -> None:
    # unsigned 4 bits at scale -1, offset 0 carry -15..0; a range of 0..3 is not carried
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|4@1+ (-1,0) [-15|0]')
    assert not errors(check_text(text), "range-raw")
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|4@1+ (-1,0) [0|3]')
    assert only(errors(check_text(text), "range-raw")).signal == "Mode"


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
    finding = only(errors(check_text(text), "start-value"))
    assert finding.signal == "Speed" and "310" in finding.text
    assert finding.line == line_of(text, "SG_ 256 Speed 31000")


def test_start_value_outside_the_raw_field() -> None:
    text = GOOD.replace('BA_ "GenSigStartValue" SG_ 256 Mode 0;', 'BA_ "GenSigStartValue" SG_ 256 Mode 16;')
    finding = only(errors(check_text(text), "start-value"))
    assert finding.signal == "Mode" and "4-bit" in finding.text


def test_missing_start_value_uses_raw_zero() -> None:
    # no GenSigStartValue: the bench starts at raw 0, i.e. the offset; -40 lies outside [0|100]
    text = GOOD.replace(' SG_ Mode : 16|4@1+ (1,0) [0|3]', ' SG_ Mode : 16|8@1+ (1,-40) [0|100]').replace(
        'BA_ "GenSigStartValue" SG_ 256 Mode 0;\n', "").replace(
        'VAL_ 256 Mode 0 "OFF" 1 "LOW" 2 "HIGH" 3 "AUTO" ;\n', "")
    result = check_text(text)
    assert only(warnings(result, "start-value")).signal == "Mode"
    finding = only(errors(result, "start-value"))
    assert "raw 0" in finding.text and "-40" in finding.text


# -- end-to-end layout ---------------------------------------------------------------------------------------
def test_e2e_counter_misplaced() -> None:
    text = GOOD.replace(" SG_ AliveCounter : 48|4@1+", " SG_ AliveCounter : 52|4@1+")
    finding = only(errors(check_text(text), "e2e"))
    assert (finding.signal, finding.line) == ("AliveCounter", line_of(text, " SG_ AliveCounter "))
    optional = check_text(text, e2e_mode="optional")
    assert not errors(optional, "e2e") and only(warnings(optional, "e2e")).signal == "AliveCounter"


def test_e2e_checksum_signed_big_endian() -> None:
    text = GOOD.replace(" SG_ Checksum : 56|8@1+", " SG_ Checksum : 63|8@0-")
    finding = only(errors(check_text(text), "e2e"))
    assert "big-endian" in finding.text and "signed" in finding.text


def test_e2e_missing_checksum() -> None:
    text = GOOD.replace(' SG_ Checksum : 56|8@1+ (1,0) [0|255] "-" TESTER\n', "")
    finding = only(errors(check_text(text), "e2e"))
    assert "no 8-bit checksum at bit 56" in finding.text and finding.line == line_of(text, "BO_ 256 ECU_Status")


def test_e2e_auto_is_optional_for_a_foreign_database() -> None:
    text = GOOD.replace(' SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "-" TESTER\n', "").replace(
        ' SG_ Checksum : 56|8@1+ (1,0) [0|255] "-" TESTER\n', "")
    result = check_text(text)
    assert result.e2e == "optional" and result.accepted
    assert only(warnings(result, "e2e")).line == 1
    required = check_text(text, e2e_mode="required")
    assert len(errors(required, "e2e")) == 2 and not required.accepted


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
    text = text.replace(" SG_ AliveCounter : 48|4@1+", " SG_ AliveCounter : 52|4@1+")
    path = tmp_path / "odd.dbc"
    path.write_bytes(text.replace("\n", eol).encode("cp1252"))
    result = check_file(path)
    assert result.encoding == "cp1252"
    assert only(errors(result, "e2e")).line == line_of(text, "SG_ AliveCounter")
    assert result.warnings == [] and {f.kind for f in result.errors} == {"e2e"}
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
    assert f"{path}: accepted: 0 errors, 0 warnings" in out


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
    assert main(["dbc", "check"]) == 0
    out = capsys.readouterr().out
    assert f"{CHASSIS_DBC}: accepted" in out and f"{BENCH_DBC}: accepted" in out


def test_cli_e2e_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "plain.dbc"
    path.write_text(GOOD.replace(' SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "-" TESTER\n', "").replace(
        ' SG_ Checksum : 56|8@1+ (1,0) [0|255] "-" TESTER\n', ""))
    assert main(["dbc", "check", str(path)]) == 0
    assert main(["dbc", "check", "--e2e", "required", str(path)]) == 1
    assert main(["dbc", "--e2e", "required"]) == 2      # the option belongs to check
    assert "only for 'bench dbc check" in capsys.readouterr().err.replace("\n", "")


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
    "issue_725.dbc": "start-value",           # GenSigStartValue 254, range [0|250]
    "issue_199.dbc": "load",                  # a standard id wider than 11 bits: cantools refuses the file
    "multiplex.dbc": "multiplex",
    "motohawk.dbc": "cycle-time",             # no GenMsgCycleTime anywhere
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
def test_corpus_accepts_only_files_without_messages() -> None:
    """Every message of the corpus lacks something the restbus needs (a cycle time at least), so only the
    files with no message at all are accepted (with a warning)."""
    results = [check_file(p) for p in CORPUS_FILES]
    accepted = {r.path.name for r in results if r.accepted}
    assert accepted and all(r.messages == 0 for r in results if r.accepted)
    assert all(r.findings for r in results)
