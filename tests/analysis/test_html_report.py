"""The HTML report: self-contained, escaped, complete without a script, and, loaded in
headless Chromium, a working step-by-step player.

The browser tests need Chromium (Debian package ``chromium``; ``.ci/run`` installs it).
Without it they are skipped on a developer's machine, and fail when ``CI`` is set: CI
must not hide a missing feature.
"""

from __future__ import annotations

import re
import subprocess
from dataclasses import dataclass
from html.parser import HTMLParser
from pathlib import Path

import pytest

from analysis.cli import main
from analysis.html_report import _script_json, render_html
from analysis.netdraw import token_text
from analysis.outcome import FileOutcome
from analysis.pipeline import CheckOptions, check_file
from analysis.report import (
    MAX_TRACE_STEPS,
    Evidence,
    PropertyResult,
    Report,
    StateSpaceFigures,
    Step,
    Verdict,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import compile_file
from coral_lang.net import Net, format_tokens
from tests.analysis.nets import make_net
from tests.conftest import EXAMPLES

POOL = str(EXAMPLES / "pool_mission" / "pool_mission.coral")
DEADLOCK = str(EXAMPLES / "faulty" / "deadlock.coral")


@dataclass(frozen=True)
class _Trace:
    """The deadlock counterexample of ``DEADLOCK`` as verify finds it, replayed."""

    net: Net
    steps: tuple[Step, ...]
    markings: list[tuple[int, ...]]  # markings[k]: after step k (0: the initial one)

    def place_ids(self, marking: tuple[int, ...]) -> set[str]:
        return {f"p{i}" for i, n in enumerate(marking) if n}


def _deadlock_trace() -> _Trace:
    net = compile_file(DEADLOCK).net
    assert net is not None
    evidence = verify(net, VerifyOptions(structural=False)).property("deadlock").evidence
    assert evidence is not None and len(evidence.trace) == 5
    markings = [net.initial_marking()]
    for step in evidence.trace:
        markings.append(net.fire(markings[-1], net.transition(step.transition)))
    return _Trace(net, evidence.trace, markings)


def _report(tmp_path: Path, *args: str, code: int, name: str = "report.html") -> Path:
    out = tmp_path / name
    assert main([*args, "--format", "html", "-o", str(out)]) == code
    return out


# -- a small DOM for reading pages ------------------------------------------------------

_VOID = {"meta", "br", "img", "input", "link", "hr", "wbr", "col", "source", "area", "base"}


class Element:
    """An element of a parsed page: tag, attributes, text content, children."""

    def __init__(self, tag: str, attrs: dict[str, str]) -> None:
        self.tag = tag
        self.attrs = attrs
        self.children: list[Element] = []
        self.parts: list[str] = []

    @property
    def classes(self) -> set[str]:
        return set(self.attrs.get("class", "").split())

    @property
    def text(self) -> str:
        return "".join(self.parts)

    def find_all(self, tag: str = "", cls: str = "", **attrs: str) -> list[Element]:
        found = []
        for child in self.children:
            if (
                (not tag or child.tag == tag)
                and (not cls or cls in child.classes)
                and all(child.attrs.get(k.replace("_", "-")) == v for k, v in attrs.items())
            ):
                found.append(child)
            found.extend(child.find_all(tag, cls, **attrs))
        return found

    def find(self, tag: str = "", cls: str = "", **attrs: str) -> Element:
        found = self.find_all(tag, cls, **attrs)
        assert found, f"no <{tag} class={cls} {attrs}>"
        return found[0]


class _Parser(HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.root = Element("#document", {})
        self.stack = [self.root]

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        element = Element(tag, {k: v or "" for k, v in attrs})
        self.stack[-1].children.append(element)
        if tag not in _VOID:
            self.stack.append(element)

    def handle_startendtag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.stack[-1].children.append(Element(tag, {k: v or "" for k, v in attrs}))

    def handle_endtag(self, tag: str) -> None:
        for depth in range(len(self.stack) - 1, 0, -1):
            if self.stack[depth].tag == tag:
                del self.stack[depth:]
                return

    def handle_data(self, data: str) -> None:
        for element in self.stack:
            element.parts.append(data)


def parse(page: str) -> Element:
    """The page as a tree of `Element`."""
    parser = _Parser()
    parser.feed(page)
    parser.close()
    return parser.root


# -- without a browser ------------------------------------------------------------------


@pytest.mark.slow
def test_the_page_is_self_contained(tmp_path: Path) -> None:
    page = _report(tmp_path, POOL, DEADLOCK, code=1).read_text()
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    lowered = page.lower()
    for outside in ("http://", "https://", "<link", "@import", "url(", " src=", "//cdn"):
        assert outside not in lowered, outside
    ids = re.findall(r'\sid="([^"]+)"', page)
    assert len(ids) == len(set(ids)), "duplicate ids"


def test_verdicts_drawing_invariants_and_figures_of_the_pool_mission(tmp_path: Path) -> None:
    page = _report(tmp_path, POOL, code=0).read_text()
    dom = parse(page)
    rows = dom.find("table", "verdicts").find_all("tr", "prop")
    assert len(rows) == 12
    assert [row.find("span", "badge").text for row in rows] == ["proven"] * 12
    assert "assert never { on_site, docking_started }" in rows[9].text
    figure = dom.find("figure", "net-figure")
    assert len(figure.find_all("g", "place")) == 58
    assert len(figure.find_all("g", "transition")) == 79
    assert dom.find("div", "P-inv").find_all("li")[0].text.startswith("start + init_ok")
    figures = dom.find("table", "figures").text
    assert "states82" in figures.replace(" ", "") and "edges139" in figures.replace(" ", "")
    # nothing violated; the witnesses of the reachability properties are replayed
    witnesses = dom.find_all("section", "cx")
    assert all("witness" in w.attrs["class"] for w in witnesses)
    assert [w.attrs["id"] for w in witnesses] == ["f0-wit-final_reachable", "f0-wit-assert-2"]
    assert "<h3>Counterexamples</h3>" not in page and "<h3>Witnesses</h3>" in page
    link = rows[2].find("a")
    assert link.attrs["href"] == "#f0-wit-final_reachable" and link.text.startswith("witness, ")


def test_each_step_is_listed_with_its_source_and_marking_without_script(tmp_path: Path) -> None:
    dom = parse(_report(tmp_path, DEADLOCK, code=1).read_text())
    (player,) = [p for p in dom.find_all("section", "cx") if p.attrs["id"] == "f0-cx-deadlock"]
    steps = player.find("ol", "steps").find_all("li")
    assert [li.attrs["data-step"] for li in steps] == ["0", "1", "2", "3", "4", "5"]
    assert "initial marking" in steps[0].text and "{ start }" in steps[0].text
    trace = _deadlock_trace()
    source = Path(DEADLOCK).read_text().splitlines()
    for k, step in enumerate(trace.steps, start=1):
        item = steps[k]
        assert step.description in item.text and step.span is not None
        assert f"deadlock.coral:{step.span.line}" in item.find("span", "loc").text
        marked = item.find("pre", "excerpt").find("mark")
        assert marked.text == f"{step.span.line}{source[step.span.line - 1]}"
        after = format_tokens(trace.net.marking_dict(trace.markings[k]).items())
        assert f"marking after: {after}" in item.find("span", "after").text
    assert "{ abort*2 }" in steps[5].text
    assert "hidden" in player.find("div", "controls").attrs  # buttons need the script
    assert len(player.find_all("g", "place")) == 13


def test_mission_text_is_escaped(tmp_path: Path) -> None:
    name = tmp_path / "a<b&c>.coral"
    source = (
        Path(DEADLOCK)
        .read_text()
        .replace(
            "transition set_heading",
            "# <script>alert('x')</script> & <b>bold</b>\ntransition set_heading",
        )
    )
    name.write_text(source)
    page = _report(tmp_path, str(name), code=1).read_text()
    assert "<script>alert" not in page and "<b>bold</b>" not in page
    assert "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt; &amp; &lt;b&gt;bold&lt;/b&gt;" in page
    assert "a&lt;b&amp;c&gt;.coral" in page and "a<b&c>" not in page
    # each counterexample's data (deadlock, final_always_reachable, terminates), the
    # witness of final_reachable, the player
    assert page.count("<script") == 5
    assert (
        _script_json({"x": "</script><b>&"})
        == '{"x":"\\u003c/script\\u003e\\u003cb\\u003e\\u0026"}'
    )


def test_unreadable_and_uncompilable_files_have_their_own_sections(tmp_path: Path) -> None:
    broken = str(EXAMPLES / "faulty" / "unhandled_reply.coral")
    page = _report(tmp_path, broken, str(tmp_path / "missing.coral"), code=2).read_text()
    dom = parse(page)
    first, second = dom.find_all("section", "file")
    assert "CORAL106" in first.find("table", "diagnostics").text
    assert "Not verified" in first.text and first.find_all("table", "verdicts") == []
    assert "Cannot read this file: no such file" in second.text
    assert render_html([FileOutcome("x.coral", input_error="gone")]).count('class="file"') == 1


def test_builtin_layout_is_selectable(tmp_path: Path) -> None:
    page = _report(tmp_path, DEADLOCK, "--net-layout", "builtin", code=1).read_text()
    figure = parse(page).find("figure", "net-figure")
    assert figure.attrs["data-layout"] == "builtin"
    assert len(figure.find_all("circle")) == 13


# -- in a browser -----------------------------------------------------------------------


def _browser(chromium: str, tmp_path: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            f"--user-data-dir={tmp_path / 'chromium-profile'}",
            "--virtual-time-budget=5000",
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


def _dom_after_script(chromium: str, tmp_path: Path, url: str) -> Element:
    completed = _browser(chromium, tmp_path, "--dump-dom", url)
    assert completed.returncode == 0, completed.stderr[-2000:]
    assert "<body" in completed.stdout, completed.stderr[-2000:]
    return parse(completed.stdout)


@pytest.mark.slow
def test_browser_renders_the_table_and_the_drawing(chromium: str, tmp_path: Path) -> None:
    page = _report(tmp_path, POOL, code=0)
    dom = _dom_after_script(chromium, tmp_path, page.as_uri())
    assert len(dom.find("table", "verdicts").find_all("tr", "prop")) == 12
    svg = dom.find("figure", "net-figure").find("svg", "net")
    assert len(svg.find_all("g", "place")) == 58


@pytest.mark.slow
def test_browser_player_opens_at_the_step_in_the_address(chromium: str, tmp_path: Path) -> None:
    page = _report(tmp_path, DEADLOCK, code=1)
    dom = _dom_after_script(chromium, tmp_path, page.as_uri() + "#step=3")
    player = dom.find("section", "cx")
    assert "hidden" not in player.find("div", "controls").attrs
    trace = _deadlock_trace()
    net, third = trace.net, trace.steps[2]
    assert player.find("output", "pos").text == f"step 3 of 5: {third.description}"
    current = [li.attrs["data-step"] for li in player.find_all("li", "current")]
    assert current == ["3"]
    fired = player.find_all("g", "fired")  # the transition and its arcs
    expected = f"t{net.transition_index(third.transition)}"
    assert {g.attrs.get("data-node") or g.attrs.get("data-t") for g in fired} == {expected}
    assert len([g for g in fired if "transition" in g.classes]) == 1
    arcs = net.transition(third.transition)
    assert len([g for g in fired if "arc" in g.classes]) == len(arcs.inputs) + len(arcs.outputs)
    tokens = {
        g.attrs["data-node"]: g.find("text", "tokens").text for g in player.find_all("g", "place")
    }
    assert tokens == {f"p{i}": token_text(n) for i, n in enumerate(trace.markings[3])}
    assert set(tokens.values()) == {"", "\u2022"}
    changed = {g.attrs["data-node"] for g in player.find_all("g", "changed")}
    before, after = trace.markings[2], trace.markings[3]
    assert changed == {
        f"p{i}" for i, (m, n) in enumerate(zip(before, after, strict=True)) if m != n
    }
    assert changed
    hit = player.find_all("span", "hit")
    assert third.span is not None and [h.attrs["data-line"] for h in hit] == [str(third.span.line)]
    assert "disabled" not in player.find("button", data_go="next").attrs


@pytest.mark.slow
def test_browser_buttons_move_through_the_steps(chromium: str, tmp_path: Path) -> None:
    page = _report(tmp_path, DEADLOCK, code=1)
    driven = tmp_path / "driven.html"
    clicks = (
        "<script>var b=function(go){document.querySelector('[data-go=\"'+go+'\"]').click();};"
        "b('next');b('next');b('last');b('prev');"
        "document.body.setAttribute('data-address',location.hash);</script></body>"
    )
    driven.write_text(page.read_text().replace("</body>", clicks))
    dom = _dom_after_script(chromium, tmp_path, driven.as_uri())
    player = dom.find("section", "cx")
    fourth = _deadlock_trace().steps[3]
    assert player.find("output", "pos").text == f"step 4 of 5: {fourth.description}"
    assert dom.find("body").attrs["data-address"] == "#cx=f0-cx-deadlock&step=4"
    assert "disabled" not in player.find("button", data_go="prev").attrs
    dom = _dom_after_script(chromium, tmp_path, page.as_uri())  # no address: step 0
    assert dom.find("output", "pos").text == "step 0 of 5: initial marking"
    assert "disabled" in dom.find("button", data_go="prev").attrs
    assert "disabled" not in dom.find("button", data_go="next").attrs


@pytest.mark.slow
def test_browser_screenshot(chromium: str, tmp_path: Path) -> None:
    page = _report(tmp_path, DEADLOCK, code=1)
    shot = tmp_path / "deadlock-report.png"
    completed = _browser(
        chromium,
        tmp_path,
        f"--screenshot={shot}",
        "--window-size=1280,2000",
        page.as_uri() + "#step=3",
    )
    assert completed.returncode == 0, completed.stderr[-2000:]
    data = shot.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n") and len(data) > 20_000
    print(f"screenshot of the deadlock report at step 3: {shot}")


def test_findings_are_located_in_the_verdict_table() -> None:
    path = str(EXAMPLES / "faulty" / "dead_transition.coral")
    outcome = check_file(path, CheckOptions(verify=VerifyOptions(structural=False)))
    assert outcome.net is not None
    dom = parse(render_html([outcome], layout="builtin"))
    row = next(
        r
        for r in dom.find("table", "verdicts").find_all("tr", "prop")
        if r.attrs["data-key"] == "dead_transitions"
    )
    items = [li.text for li in row.find("ul", "findings").find_all("li")]
    span = outcome.net.transition("record_dock").span
    assert f"{span} transition 'record_dock' can never fire" in items


def test_a_long_trace_shows_its_first_steps_and_counts_the_rest() -> None:
    size = 4
    net = make_net(
        "ring",
        {f"p{i}": int(i == 0) for i in range(size)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % size}": 1}) for i in range(size)},
    )
    total = MAX_TRACE_STEPS + 12
    steps = tuple(
        Step(n, f"t{(n - 1) % size}", "mission", f"t{(n - 1) % size} fires")
        for n in range(1, total + 1)
    )
    evidence = Evidence(trace=steps, marking={"p0": 1} if total % size == 0 else None)
    prop = PropertyResult("deadlock", "no deadlock", Verdict.VIOLATED, "m", "d", evidence)
    figures = StateSpaceFigures(4, 4, 1, 1, {}, True, None, False, 0.0, 0.0)
    report = Report("ring", net.digest(), (), figures, [prop])
    page = render_html([FileOutcome("ring.pnml", net=net, report=report)], layout="builtin")
    section = parse(page).find("section", "cx")
    assert len(section.find("ol", "steps").find_all("li")) == MAX_TRACE_STEPS + 1
    note = section.find("p", "more-steps").text
    assert "... 12 more steps (full trace in --format json)" in note


def test_a_part_says_which_mission_verifies_it() -> None:
    part = check_file(EXAMPLES / "pool_mission" / "docking.coral", CheckOptions())
    page = render_html([part], layout="builtin")
    section = parse(page).find("section", "file")
    assert section.find("span", "badge").text == "part"
    assert "A part of" in section.text and "pool_mission.coral" in section.text
    assert "Not verified: fix the errors first" not in page
