"""Check that every relative link in README.md and examples/*.md points to an existing file (and,
for a `#anchor` into a Markdown file, to one of its headings, slugged as GitHub does).

    python examples/check_links.py        # exit 1 and one line per broken link
"""

# ruff: noqa: T201  (a check prints what it finds)

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
FENCE = re.compile(r"```.*?```", re.S)


def slug(heading: str) -> str:
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return {slug(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.M)}


def broken(doc: Path) -> list[str]:
    out = []
    for target in LINK.findall(FENCE.sub("", doc.read_text(encoding="utf-8"))):
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        file = (doc.parent / path).resolve() if path else doc
        if not file.exists():
            out.append(f"{doc.relative_to(ROOT)}: no file {target}")
        elif anchor and file.suffix == ".md" and anchor not in anchors(file):
            out.append(f"{doc.relative_to(ROOT)}: no heading #{anchor} in {file.relative_to(ROOT)}")
    return out


if __name__ == "__main__":
    docs = [ROOT / "README.md", *sorted((ROOT / "examples").glob("*.md"))]
    problems = [p for d in docs for p in broken(d)]
    print("\n".join(problems) or f"{len(docs)} documents, every relative link resolves")
    sys.exit(1 if problems else 0)
