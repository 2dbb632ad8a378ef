"""Turn the experiment reports (``docs/results/<data>/<name>.md``, written by
``eppf experiment``) into reStructuredText for the "Reproducing the
paper" page, so the page shows exactly what the commands printed.

Only the Markdown the reports use is understood: headings, paragraphs,
bullets, fenced code, pipe tables and images.
"""

import os
import re

_UNDERLINE = {1: "-", 2: "~", 3: "^"}


def _inline(text):
    """Markdown inline markup to reST: `code` to ``code``; other text escaped."""
    parts = re.split(r"(`[^`]+`)", text)
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"``{part[1:-1]}``")
        else:
            part = part.replace("\\", "\\\\").replace("|", "\\|").replace("_ ", "\\_ ")
            part = re.sub(r"(?<![\w*])\*(?![\s*])", r"\\*", part)  # a lone * would open emphasis
            out.append(part)
    return "".join(out)


def _table(rows):
    cells = [[c.strip() for c in r.strip().strip("|").split("|")] for r in rows]
    header, body = cells[0], [r for r in cells[2:]]
    lines = [".. list-table::", "   :header-rows: 1", ""]
    for row in [header] + body:
        for k, cell in enumerate(row):
            lines.append(("   * - " if k == 0 else "     - ") + (_inline(cell) or "\\ "))
    return lines + [""]


def md_to_rst(text, image_dir, top_level=1):
    """Convert one report to reST.

    Parameters
    ----------
    text : str
        The Markdown report.
    image_dir : str
        Path of the report's folder as seen from the including page, used
        for images.
    top_level : int
        reST heading level of the report's ``##`` headings (its ``#`` title
        is dropped: the including page titles it).
    """
    lines = text.splitlines()
    out, k = [], 0
    while k < len(lines):
        line = lines[k]
        if line.startswith("```"):
            end = k + 1
            while end < len(lines) and not lines[end].startswith("```"):
                end += 1
            out += [".. code-block:: none", ""] + ["   " + c for c in lines[k + 1:end]] + [""]
            k = end + 1
            continue
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            title = line[level:].strip()
            if level > 1:
                rst_level = top_level + level - 2
                out += [_inline(title), _UNDERLINE[min(rst_level, 3)] * max(len(_inline(title)), 3), ""]
            k += 1
            continue
        if line.startswith("|"):
            end = k
            while end < len(lines) and lines[end].startswith("|"):
                end += 1
            out += _table(lines[k:end])
            k = end
            continue
        image = re.fullmatch(r"!\[([^\]]*)\]\(([^)]+)\)", line.strip())
        if image:
            out += [f".. image:: {image_dir}/{image.group(2)}", f"   :alt: {image.group(1)}", ""]
            k += 1
            continue
        if line.startswith("- "):
            out.append("- " + _inline(line[2:]))
            if k + 1 < len(lines) and not lines[k + 1].startswith("- "):
                out.append("")
            k += 1
            continue
        out.append(_inline(line))
        k += 1
    return "\n".join(out) + "\n"


def write_results(results_dir, generated_dir, image_dir="/results"):
    """Convert every ``<results_dir>/<data>/<name>.md`` into ``<generated_dir>/<data>_<name>.rst``.

    Returns the list of ``(data, name)`` pairs converted.
    """
    done = []
    if not os.path.isdir(results_dir):
        return done
    os.makedirs(generated_dir, exist_ok=True)
    for data in sorted(os.listdir(results_dir)):
        folder = os.path.join(results_dir, data)
        if not os.path.isdir(folder):
            continue
        for name in sorted(os.listdir(folder)):
            if not name.endswith(".md"):
                continue
            with open(os.path.join(folder, name)) as f:
                rst = md_to_rst(f.read(), f"{image_dir}/{data}", top_level=3)
            path = os.path.join(generated_dir, f"{data}_{name[:-3]}.rst")
            old = open(path).read() if os.path.exists(path) else None
            if old != rst:
                with open(path, "w") as f:
                    f.write(rst)
            done.append((data, name[:-3]))
    return done
