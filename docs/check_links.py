"""Offline check of a built site's internal links: ``python docs/check_links.py docs/_build/html``.

Every ``href`` and ``src`` of every HTML page is parsed; a link to a file of the site that does not exist, to an
``#anchor`` that the target page does not define (an ``id`` or ``name``), and an image that is missing are each
reported with the page that holds them, and the exit status is 1. External links (``http:``, ``https:``, ``mailto:``)
are not fetched.
"""

from __future__ import annotations

import argparse
import os
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

EXTERNAL_SCHEMES = {"http", "https", "mailto", "ftp", "data", "javascript", "tel"}
LINK_ATTRIBUTES = {"href", "src"}


class PageParser(HTMLParser):
    """The ``(tag, attribute, value)`` links of a page and the anchors (``id``, ``<a name>``) it defines."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.links: list[tuple[str, str, str]] = []
        self.anchors: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for name, value in attrs:
            if value is None:
                continue
            if name == "id" or (tag == "a" and name == "name"):
                self.anchors.add(value)
            # <link rel="canonical"> and friends: only the page's own links, images and scripts are checked
            elif name in LINK_ATTRIBUTES and not (tag == "link" and name == "href" and value.startswith("http")):
                self.links.append((tag, name, value))

    handle_startendtag = handle_starttag


def parse(page: Path) -> PageParser:
    parser = PageParser()
    parser.feed(page.read_text(encoding="utf-8", errors="replace"))
    return parser


def dead_links(site: Path) -> list[str]:
    """One line per dead internal link or missing image of the site built in ``site``."""
    pages = sorted(site.rglob("*.html"))
    parsed = {page.resolve(): parse(page) for page in pages}
    problems = []
    for page, parser in parsed.items():
        where = page.relative_to(site.resolve())
        for tag, attribute, value in parser.links:
            url = urlsplit(value)
            if url.scheme in EXTERNAL_SCHEMES or url.netloc:
                continue
            if url.scheme:
                problems.append(f"{where}: {tag} {attribute}={value!r}: unknown scheme {url.scheme!r}")
                continue
            target = (page.parent / unquote(url.path)).resolve() if url.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.is_file():
                kind = "image" if tag == "img" else "link"
                problems.append(f"{where}: {kind} {value!r}: {os.path.relpath(target, site.resolve())} is missing")
                continue
            anchor = unquote(url.fragment)
            if anchor and target.suffix == ".html":
                anchors = parsed[target].anchors if target in parsed else parse(target).anchors
                if anchor not in anchors:
                    problems.append(
                        f"{where}: link {value!r}: no anchor #{anchor} in {target.relative_to(site.resolve())}"
                    )
    return problems


def main(argv: list[str] | None = None) -> int:
    arguments = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    arguments.add_argument("site", type=Path, help="the built site, e.g. docs/_build/html")
    site = arguments.parse_args(argv).site
    if not (site / "index.html").is_file():
        print(f"error: {site} holds no index.html: build the site first", file=sys.stderr)
        return 1
    problems = dead_links(site)
    for problem in problems:
        print(problem)
    pages = sum(1 for _ in site.rglob("*.html"))
    if problems:
        print(f"{len(problems)} dead internal link(s) or missing image(s) in {pages} pages", file=sys.stderr)
        return 1
    print(f"{pages} pages: every internal link, anchor and image resolves")
    return 0


if __name__ == "__main__":
    sys.exit(main())
