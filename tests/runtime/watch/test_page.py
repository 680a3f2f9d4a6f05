"""The page is one self-contained file whose script parses and which has every element
id its module documents for browser tests."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from runtime.watch import page
from runtime.watch.page import PAGE


def _script() -> str:
    [script] = re.findall(r"<script>(.*?)</script>", PAGE, flags=re.DOTALL)
    return str(script)


def test_the_script_parses(tmp_path: Path) -> None:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed: the page's script is not syntax-checked here")
    path = tmp_path / "page.js"
    path.write_text(_script(), encoding="utf-8")
    done = subprocess.run([node, "--check", str(path)], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stderr


def test_every_documented_id_is_on_the_page() -> None:
    doc = page.__doc__ or ""
    documented = set(re.findall(r"``#([a-z][a-z-]*)", doc))
    assert {"net", "commands", "marking", "telemetry", "operator", "end", "paused"} <= documented
    ids = set(re.findall(r'\bid="([a-z-]+)"', PAGE))
    assert documented <= ids, documented - ids
    assert len(re.findall(r'\bid="', PAGE)) == len(ids)  # no id given twice


def test_the_page_has_no_external_asset_and_inserts_no_html() -> None:
    assert "src=" not in PAGE and "<link" not in PAGE and "@import" not in PAGE
    assert re.findall(r"https?://[^\"' ]+", PAGE) == ["http://www.w3.org/2000/svg"]
    for sink in ("innerHTML", "outerHTML", "insertAdjacentHTML", "document.write", "eval("):
        assert sink not in PAGE, sink
    script = _script()
    # The markers the script sets and reads are the ones netdraw draws and the docs name.
    for marker in ("g.place", "g.transition", "text.tokens", "dataset.node"):
        assert marker in script, marker
    for css in ("enabled", "inflight", "offered", "fired"):
        assert f'classList.toggle("{css}"' in script or f'classList.add("{css}"' in script
    for attribute in ('"data-action"', "dataset.action", "dataset.input"):
        assert attribute.strip('"') in script
    # Operator actions carry the token as a bearer token and say they come from the page.
    assert '"Authorization": "Bearer "' in script and '"X-Coral-Client": "page"' in script
    assert 'fetch("operate", { method: "POST"' in script
