"""What users read stays true and about the tool: the figures page and README's headline block
are what benchmarks/figures_page.py makes of the results files, README stays short, relative
links lead somewhere, and no page speaks of how the project was developed."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from benchmarks import figures_page, reference_pages

ROOT = Path(__file__).resolve().parents[1]
USER_PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
# Development history belongs in results files and commit messages, not in what users read.
HISTORY = re.compile(
    r"\bstop [0-9]+|\bstops [0-9]+|this session|session's (vm|run)|not lent|was lent"
    r"|\bissue [0-9]+|\bissue #[0-9]+|\bwave [0-9]+", re.IGNORECASE)
LINK = re.compile(r"\]\(([^)#\s]+)(#[^)\s]*)?\)")


def test_the_figures_page_is_what_the_results_files_say() -> None:
    results, headlines = figures_page.load_results(), figures_page.load_headlines()
    expected = figures_page.page(results, headlines)
    assert figures_page.PAGE.read_text() == expected, (
        "docs/figures.md is stale: run .venv/bin/python benchmarks/figures_page.py")


def test_readme_headlines_are_what_the_results_files_say() -> None:
    results, headlines = figures_page.load_results(), figures_page.load_headlines()
    readme = figures_page.README.read_text()
    assert figures_page.readme_with_headlines(readme, results, headlines) == readme, (
        "README's figures are stale: run .venv/bin/python benchmarks/figures_page.py")


def test_a_headline_naming_a_missing_figure_is_refused() -> None:
    results = figures_page.load_results()
    bad = [figures_page.Headline(what="x", file="eval_pose", figure="no_such_figure")]
    with pytest.raises(KeyError, match="no_such_figure"):
        figures_page.headline_rows(results, bad)


def test_figures_are_printed_as_a_reader_reads_them() -> None:
    fmt = figures_page.format_value
    assert [fmt(15841), fmt(2.0915), fmt(0.97064), fmt(1319.6), fmt(True)] == [
        "15,841", "2.09", "0.971", "1,320", "True"]


def test_readme_is_short() -> None:
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200


@pytest.mark.parametrize("page", USER_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_pages_speak_of_the_tool_not_of_its_development(page: Path) -> None:
    hits = [m.group(0) for m in HISTORY.finditer(page.read_text())]
    assert hits == [], f"{page.relative_to(ROOT)}: {hits[:5]}"


@pytest.mark.parametrize("page", USER_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_lead_to_files(page: Path) -> None:
    missing = []
    for target, _anchor in LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target):
            continue
        if not (page.parent / target).exists():
            missing.append(target)
    assert missing == [], f"{page.relative_to(ROOT)} links to missing files: {missing}"


def test_the_cli_reference_is_what_the_parsers_say() -> None:
    assert reference_pages.CLI_PAGE.read_text() == reference_pages.cli_page(), (
        "docs/reference/cli.md is stale: run .venv/bin/python benchmarks/reference_pages.py")


def test_the_rest_reference_is_what_the_openapi_schema_says() -> None:
    assert reference_pages.REST_PAGE.read_text() == reference_pages.rest_page(), (
        "docs/reference/rest.md is stale: run .venv/bin/python benchmarks/reference_pages.py")


def test_the_settings_reference_is_what_the_settings_say() -> None:
    assert reference_pages.SETTINGS_PAGE.read_text() == reference_pages.settings_page(), (
        "docs/reference/settings.md is stale: run .venv/bin/python benchmarks/reference_pages.py")
