"""Publish the documentation: the API reference (pdoc) and the pages of docs/ as one static site.

    pip install "snapmem[docs]"
    python docs/build.py                 # -> docs/_site/index.html (open it in a browser)
    python docs/build.py --out SITE      # elsewhere

The site has ``api/`` (every public module of snapmem, from its numpy-style docstrings) and one
HTML page per Markdown page of docs/ (docs/index.md first, the architecture, the model, the
performance notes and the tutorials with their scripts), linked from ``index.html``.
"""

from __future__ import annotations

import argparse
import html
import re
import shutil
from pathlib import Path

DOCS = Path(__file__).resolve().parent
STYLE = ("body{max-width:54em;margin:2em auto;padding:0 1em;font-family:sans-serif;line-height:1.5}"
         "pre{background:#f4f4f4;padding:.6em;overflow-x:auto}code{background:#f4f4f4}"
         "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.2em .5em}")


def modules() -> list[str]:
    """snapmem and every submodule (pdoc follows ``__all__``, which names no submodules), without
    the aliases of old module paths."""
    import pkgutil

    import snapmem
    names = [m.name for m in pkgutil.walk_packages(snapmem.__path__, "snapmem.")]
    return ["snapmem"] + [n for n in names if n != "snapmem._moved"]


def pages() -> list[Path]:
    """The Markdown pages of docs/, index first, then alphabetically (tutorials last)."""
    found = sorted(p for p in DOCS.rglob("*.md") if "_site" not in p.parts and "out" not in p.parts)
    return sorted(found, key=lambda p: (p.name != "index.md" or p.parent != DOCS, "tutorials" in p.parts, str(p)))


def html_name(page: Path) -> str:
    relative = page.relative_to(DOCS).with_suffix("")
    return "_".join(relative.parts).replace("README", "index") + ".html" if relative.parts != ("index",) \
        else "index.html"


def render_page(page: Path, names: dict[str, str]) -> str:
    """One Markdown page as HTML, its links to other pages and to the API pointed at the site's files."""
    from markdown2 import markdown            # pdoc's own Markdown renderer (a pdoc dependency)
    body = markdown(page.read_text(), extras=["fenced-code-blocks", "tables", "header-ids"])
    for source, target in names.items():
        body = body.replace(f'href="{source}"', f'href="{target}"')
    title = re.search(r"<h1[^>]*>(.*?)</h1>", body)
    title = re.sub("<[^>]+>", "", title.group(1)) if title else page.stem
    nav = " | ".join(f'<a href="{t}">{html.escape(s)}</a>' for s, t in names.items() if s.endswith(".md")) \
        + ' | <a href="api/snapmem.html">API reference</a>'
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{STYLE}</style></head><body><nav>{nav}</nav>{body}</body></html>")


def build(out: Path = DOCS / "_site", api: bool = True) -> Path:
    """Write the site into ``out`` (emptied first) and return its index.html."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    if api:
        import pdoc
        pdoc.render.configure(docformat="numpy", footer_text="snapmem")
        pdoc.pdoc(*modules(), output_directory=out / "api")
    found = pages()
    names = {str(p.relative_to(DOCS)): html_name(p) for p in found}
    for page in found:         # links written relative to the page's own folder
        local = {**names, **{str(p.relative_to(page.parent)): html_name(p) for p in found
                             if p.is_relative_to(page.parent)}}
        (out / html_name(page)).write_text(render_page(page, local))
    tutorials = out / "tutorials"
    tutorials.mkdir()
    for script in sorted((DOCS / "tutorials").glob("*.py")):
        shutil.copy(script, tutorials / script.name)
        names[f"{script.name}"] = f"tutorials/{script.name}"
    index = out / "tutorials_index.html"
    if index.exists():                      # the tutorials' index links to their scripts
        text = index.read_text()
        for script in tutorials.glob("*.py"):
            text = text.replace(f'href="{script.name}"', f'href="tutorials/{script.name}"')
        index.write_text(text)
    return out / "index.html"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DOCS / "_site", help="site folder (default docs/_site)")
    parser.add_argument("--no-api", action="store_true", help="only the Markdown pages (no pdoc)")
    args = parser.parse_args(argv)
    index = build(args.out, api=not args.no_api)
    print(f"docs: {index}")


if __name__ == "__main__":
    main()
