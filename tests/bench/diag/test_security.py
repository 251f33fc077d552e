"""The seed/key of SecurityAccess: the documented algorithm (docs/contract/diagnostics.md DIAG-SEC-01, its worked
example), and an external node's secret algorithm named in bench.toml, whose failures are one line each."""

from __future__ import annotations

import sys
import types
from collections.abc import Iterator
from pathlib import Path

import pytest

from bench.diag.declaration import load_declaration
from bench.diag.security import documented_key
from bench.diag.tester import key_function
from bench.errors import BenchError
from tests.repo import ROOT

SBW = load_declaration(ROOT / "dbc" / "diagnostics.toml").node("SBW")


def test_the_worked_example_of_the_contract() -> None:
    """DIAG-SEC-01: SBW (C = 0x53425701), seed 0x12345678 -> key 0x1EA51905."""
    assert SBW.security_constant == 0x53425701
    assert documented_key(bytes.fromhex("12345678"), SBW.security_constant) == bytes.fromhex("1EA51905")


def test_a_node_without_a_function_uses_the_documented_algorithm() -> None:
    key = key_function(SBW, {}, external=True)
    assert key(1, bytes.fromhex("12345678"), None) == bytes.fromhex("1EA51905")


@pytest.fixture
def secret_module() -> Iterator[str]:
    module = types.ModuleType("bench_test_secret_keys")

    def good(level: int, seed: bytes, params: object) -> bytes:
        return bytes(b ^ 0xFF for b in seed)

    def broken(level: int, seed: bytes, params: object) -> bytes:
        raise ValueError("no key for this seed")

    def wrong_type(level: int, seed: bytes, params: object) -> str:
        return "not bytes"

    module.good, module.broken, module.wrong_type = good, broken, wrong_type   # type: ignore[attr-defined]
    module.not_callable = 42   # type: ignore[attr-defined]
    sys.modules[module.__name__] = module
    yield module.__name__
    del sys.modules[module.__name__]


def test_an_external_nodes_function_is_used(secret_module: str) -> None:
    key = key_function(SBW, {"SBW": f"{secret_module}:good"}, external=True)
    assert key(1, b"\x00\x01\x02\x03", None) == b"\xff\xfe\xfd\xfc"
    # the node simulated by the bench answers the documented key, whatever bench.toml names for a real one
    assert key_function(SBW, {"SBW": f"{secret_module}:good"}, external=False)(1, bytes.fromhex("12345678"), None) \
        == bytes.fromhex("1EA51905")


@pytest.mark.parametrize("name, words", [
    ("broken", "raised ValueError: no key for this seed (seed 00010203)"),
    ("wrong_type", "returned str, not bytes (seed 00010203)"),
])
def test_a_failing_function_is_one_line_naming_it(secret_module: str, name: str, words: str) -> None:
    key = key_function(SBW, {"SBW": f"{secret_module}:{name}"}, external=True)
    with pytest.raises(BenchError) as failure:
        key(1, b"\x00\x01\x02\x03", None)
    text = str(failure.value)
    assert "\n" not in text and f"security SBW = '{secret_module}:{name}'" in text and text.endswith(words)


@pytest.mark.parametrize("spec, words", [
    ("no_such_module_anywhere:key", "cannot load: ModuleNotFoundError"),
    ("{module}:missing", "cannot load: AttributeError"),
    ("{module}:not_callable", "not a function"),
])
def test_a_function_that_cannot_be_loaded_is_one_line(secret_module: str, spec: str, words: str) -> None:
    spec = spec.format(module=secret_module)
    with pytest.raises(BenchError) as failure:
        key_function(SBW, {"SBW": spec}, external=True)
    assert "\n" not in str(failure.value) and words in str(failure.value) and spec in str(failure.value)


def test_bench_toml_names_the_function_per_node(tmp_path: Path) -> None:
    from bench.config import load_config

    text = (ROOT / "bench.toml").read_text(encoding="utf-8").replace(
        '[diagnostics]\nfile = "dbc/diagnostics.toml"', '[diagnostics]\nfile = "dbc/diagnostics.toml"\n'
        'security = { SBW = "my_keys:sbw_key" }')
    config = tmp_path / "bench.toml"
    config.write_text(text.replace('"dbc/', f'"{ROOT}/dbc/').replace('"docs/', f'"{ROOT}/docs/'), encoding="utf-8")
    assert load_config(config).security == {"SBW": "my_keys:sbw_key"}
