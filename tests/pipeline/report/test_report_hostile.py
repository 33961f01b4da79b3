"""`r2s report` on hostile programs (issue 22, item 11): frame ids, strategy names, error messages and programs
written to break out of Markdown and HTML. report.md is rendered by an independent CommonMark renderer
(markdown-it-py, GitHub's table extension on) and both files are parsed as HTML: the only elements are the
report's own, the only links point at the plots we wrote or at the page's own sections, and every hostile string
is shown as its text. Also: `--out` never deletes what the report did not write."""

from __future__ import annotations

import html
import re
from html.parser import HTMLParser
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from pipeline.programs import failure_row, programs_table, result_row
from pipeline.report.document import md_code, md_html_text, md_text
from pipeline.report.plots import PLOT_FILES
from synth.config import SynthConfig
from synth.synthesize import synthesize
from tests.support import run_r2s

markdown_it = pytest.importorskip("markdown_it")

SCRIPT = "<script>alert(1)</script>"
IFRAME = "<iframe src=javascript:alert(2)>"
LINK = "[click](javascript:alert(3))"
IMAGE = "![p](http://example.com/p.png)"  # a renderer reading Markdown inside HTML would load it (issue 35, item 14)
HOSTILE_IDS = (f"{SCRIPT}/0", f"x{IFRAME}/1", f"{LINK}/2", "&lt;script&gt;/3", "# heading\n\n<b>x</b>/4",
               "1. item | cell `code`/5", f"{IMAGE}/6")
HOSTILE_PROGRAM = f"car = new Car ahead of ego by Range(0, 1)\n```\n{SCRIPT}\n````\n{IFRAME}\n"
HOSTILE_ERROR = f"boom {SCRIPT} {LINK}\n\n<img src=x onerror=alert(4)>"


@pytest.fixture(scope="module")
def hostile_report(real_frames, tmp_path_factory) -> Path:
    config = SynthConfig()
    rows = []
    for k, (fid, scene) in enumerate(zip(HOSTILE_IDS, real_frames)):
        row = result_row(synthesize(scene, config))
        row.update(frame_id=fid, program=HOSTILE_PROGRAM if k % 2 == 0 else row["program"],
                   strategy=f"auto{IFRAME}" if k < 3 else "auto")
        rows.append(row)
        rows.append(failure_row(f"err{SCRIPT}{k}", "error", HOSTILE_ERROR, len(scene.others), config))
    where = tmp_path_factory.mktemp("hostile")
    pq.write_table(programs_table(rows), where / "programs.parquet")
    proc = run_r2s("report", str(where / "programs.parquet"), "--frames", f"frames{SCRIPT}.parquet",
                   "--out", str(where / "report"))
    assert proc.returncode == 0, proc.stderr
    return where / "report"


class _Elements(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data):
        self.text.append(data)


def _elements(page: str) -> _Elements:
    parser = _Elements()
    parser.feed(page)
    return parser


REPORT_TAGS = {"html", "head", "meta", "title", "style", "body", "main", "h1", "h2", "p", "nav", "a", "div",
               "table", "thead", "tbody", "tr", "th", "td", "figure", "img", "figcaption", "b", "details", "summary",
               "pre", "code", "em", "strong"}


def _assert_only_ours(elements: _Elements) -> None:
    assert {tag for tag, _ in elements.tags} <= REPORT_TAGS, {tag for tag, _ in elements.tags} - REPORT_TAGS
    for tag, attrs in elements.tags:
        assert not any(name.startswith("on") for name in attrs), (tag, attrs)
        if tag == "a":
            assert attrs.get("href", "").startswith("#"), attrs
        if tag == "img":
            assert attrs["src"] in PLOT_FILES or attrs["src"].startswith("data:image/png;base64,"), attrs


def test_report_md_renders_every_hostile_string_as_text(hostile_report):
    md = (hostile_report / "report.md").read_text()
    rendered = markdown_it.MarkdownIt("commonmark").enable("table").render(md)
    elements = _elements(rendered)
    _assert_only_ours(elements)
    text = "".join(elements.text)
    for fid in HOSTILE_IDS:
        assert " ".join(fid.splitlines()).strip() in text  # shown, as text, one line
    assert HOSTILE_PROGRAM.rstrip("\n") in text  # the whole program inside one code block: the fence held


def test_report_md_summaries_are_text_to_a_renderer_reading_markdown_inside_html(hostile_report):
    """A program's summary line sits in report.md's one HTML block (<details><summary>), which CommonMark leaves as
    it is (the test above) but some renderers read as Markdown: read so, it is text too, and the same text."""
    md = (hostile_report / "report.md").read_text()
    summaries = re.findall(r"<summary>(.*?)</summary>", md)
    assert any(html.unescape(s).startswith(f"{IMAGE}/6 ") for s in summaries), summaries
    for summary in summaries:
        assert "<" not in summary and "[" not in summary and "http:" not in summary
        elements = _elements(markdown_it.MarkdownIt("commonmark").render(summary))
        assert [tag for tag, _ in elements.tags] == ["p"], summary
        assert "".join(elements.text).strip() == html.unescape(summary)


@pytest.mark.parametrize("text", [IMAGE, LINK, SCRIPT, "- a *b* _c_ `d` ~~e~~ \\ | f", "&amp; &#60;x&#62;",
                                  "www.example.com http://example.com <http://x.y>", "line\nbreak\u2028more", ""])
def test_md_html_text_is_the_text_in_html_and_in_markdown(text):
    shown = " ".join(text.splitlines()).strip()
    escaped = md_html_text(text)
    as_html = _elements(markdown_it.MarkdownIt("commonmark").render(f"<details><summary>{escaped}</summary>\n"))
    assert {tag for tag, _ in as_html.tags} == {"details", "summary"} and "".join(as_html.text).strip() == shown
    as_markdown = _elements(markdown_it.MarkdownIt("commonmark").enable("table").render(escaped + "\n"))
    assert {tag for tag, _ in as_markdown.tags} <= {"p"} and "".join(as_markdown.text).strip() == shown


def test_report_html_has_only_its_own_elements(hostile_report):
    page = (hostile_report / "report.html").read_text()
    elements = _elements(page)
    _assert_only_ours(elements)
    text = "".join(elements.text)
    assert SCRIPT in text and IFRAME in text and HOSTILE_PROGRAM.rstrip("\n") in text


@pytest.mark.parametrize("text", [
    SCRIPT, IFRAME, LINK, "&amp; &#60;script&#62;", "- item", "+ item", "1. first", "7) seventh", "## title",
    "a | b", "`code` **bold** _em_ ~~strike~~ \\escaped", "line\nbreak\r\nand\u2028more", "    indented code",
    "<!-- comment -->", "![img](x.png)", "<http://example.com>", "===", "",
])
def test_md_text_is_shown_verbatim(text):
    rendered = markdown_it.MarkdownIt("commonmark").enable("table").render(md_text(text) + "\n")
    elements = _elements(rendered)
    assert {tag for tag, _ in elements.tags} <= {"p"}, rendered
    assert "".join(elements.text).strip() == " ".join(text.splitlines()).strip()


@pytest.mark.parametrize("code", ["```", "a\n```\nb", "````\n```", "~~~\nx", "`` ` ``", "x\n" * 3])
def test_md_code_keeps_its_fence(code):
    rendered = markdown_it.MarkdownIt("commonmark").render(md_code(code) + "\n")
    elements = _elements(rendered)
    assert [tag for tag, _ in elements.tags] == ["pre", "code"], rendered
    assert "".join(elements.text).rstrip("\n") == code.rstrip("\n")


def test_out_never_deletes_a_users_files(hostile_report, tmp_path):
    """A folder named like a report file (report.md/) is the user's: refused, nothing deleted."""
    out = tmp_path / "report"
    (out / "report.md").mkdir(parents=True)
    (out / "report.md" / "notes.txt").write_text("keep me")
    proc = run_r2s("report", str(hostile_report.parent / "programs.parquet"), "--out", str(out))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert (out / "report.md" / "notes.txt").read_text() == "keep me"
