"""Check (or fix) that eppf's prose uses one spelling: American, as scikit-learn.

Prose is the docstrings and comments of ``eppf/`` (Python, Cython and C
sources) and the text of ``docs/*.rst`` and ``README.md`` outside inline
literals. String literals that the code prints or writes (messages, report
lines, file contents) are left alone: changing them changes outputs.

    python scripts/american_spelling.py          # list British spellings, exit 1 if any
    python scripts/american_spelling.py --fix    # rewrite them in place
"""
import argparse
import io
import pathlib
import re
import sys
import tokenize

ROOT = pathlib.Path(__file__).resolve().parent.parent

_IZE_STEMS = ("voxel|normal|organ|optim|initial|serial|recogn|minim|maxim|summar|visual|general|parallel|vector"
              "|discret|standard|regular|random|character|categor|special|penal|util|quant|token|emphas|real"
              "|custom|priorit|final|synchron|author|capital|central|stabil|neutral|local|linear")
# (pattern, replacement); the replacement keeps the match's capitals
_RULES = [
    (re.compile(r"\b(%s)is(e|ed|es|ing|ation|ations|er|ers)\b" % _IZE_STEMS, re.I), r"\1iz\2"),
    (re.compile(r"\banalys(e|ed|ing)\b", re.I), r"analyz\1"),
    (re.compile(r"neighbour", re.I), "neighbor"),
    (re.compile(r"behaviour", re.I), "behavior"),
    (re.compile(r"colour", re.I), "color"),
    (re.compile(r"favour", re.I), "favor"),
    (re.compile(r"\bcentre(s)?\b", re.I), r"center\1"),
    (re.compile(r"\bcentr(ed|ing)\b", re.I), r"center\1"),
    (re.compile(r"\bmodell(ing|ed)\b", re.I), r"model\1"),
    (re.compile(r"\blabell(ing|ed)\b", re.I), r"label\1"),
    (re.compile(r"\b(travel|cancel|signal)l(ing|ed)\b", re.I), r"\1\2"),
    (re.compile(r"\bgrey(s)?\b", re.I), r"gray\1"),
    (re.compile(r"\b(kilo|milli|centi)?metre(s)?\b", re.I), r"\1meter\2"),
    (re.compile(r"\bartefact", re.I), "artifact"),
    (re.compile(r"\blicence", re.I), "license"),
]
_ALL = re.compile("|".join("(?:%s)" % p.pattern for p, _ in _RULES), re.I)


def _american(text):
    """``text`` with every British spelling of ``_RULES`` replaced (capitals kept)."""
    for pattern, repl in _RULES:
        def fix(m, repl=repl):
            new = m.expand(repl)
            if len(m.group(0)) > 1 and m.group(0).isupper():
                return new.upper()
            return new[0].upper() + new[1:] if m.group(0)[0].isupper() else new
        text = pattern.sub(fix, text)
    return text


def _python_prose(src):
    """(start, end) offsets of the comments and docstrings of Python/Cython source ``src``."""
    lines = src.splitlines(keepends=True)
    starts = [0]
    for line in lines:
        starts.append(starts[-1] + len(line))

    def offset(pos):
        return starts[pos[0] - 1] + pos[1]

    toks = list(tokenize.generate_tokens(io.StringIO(src).readline))
    spans = []
    for i, t in enumerate(toks):
        if t.type == tokenize.COMMENT:
            spans.append((offset(t.start), offset(t.end)))
        elif t.type == tokenize.STRING:
            j = i - 1
            while j >= 0 and toks[j].type in (tokenize.NL, tokenize.COMMENT):
                j -= 1
            k = i + 1
            while k < len(toks) and toks[k].type == tokenize.NL:
                k += 1
            before = j < 0 or toks[j].type in (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT)
            if before and toks[k].type in (tokenize.NEWLINE, tokenize.ENDMARKER):
                spans += _outside(src, offset(t.start), offset(t.end), _DOCTEST)
    return spans


# A docstring's examples, from a ">>>" line to the next blank line: their output is the code's.
_DOCTEST = re.compile(r"^[ \t]*>>>.*?(?=^[ \t]*$|\Z)", re.M | re.S)


def _outside(src, start, end, pattern):
    """The parts of ``src[start:end]`` outside the matches of ``pattern``, as (start, end) offsets."""
    spans, pos = [], start
    for m in pattern.finditer(src, start, end):
        spans.append((pos, m.start()))
        pos = m.end()
    spans.append((pos, end))
    return spans


def _c_prose(src):
    """(start, end) offsets of the comments of C source ``src``."""
    return [m.span() for m in re.finditer(r"/\*.*?\*/|//[^\n]*", src, re.S)]


def _text_prose(src):
    """(start, end) offsets of reST/Markdown text outside inline literals and code blocks."""
    return _outside(src, 0, len(src), re.compile(r"``.*?``|`[^`\n]*`|^```.*?^```", re.S | re.M))


def _files():
    for path in sorted((ROOT / "eppf").rglob("*")):
        if path.suffix in (".py", ".pyx", ".pxd"):
            yield path, _python_prose
        elif path.suffix == ".h":
            yield path, _c_prose
    for path in sorted((ROOT / "docs").glob("*.rst")):
        yield path, _text_prose
    yield ROOT / "README.md", _text_prose


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fix", action="store_true", help="rewrite the British spellings in place")
    args = parser.parse_args(argv)
    found = 0
    for path, prose in _files():
        src = path.read_text(encoding="utf-8")
        out, pos = [], 0
        for a, b in prose(src):
            out.append(src[pos:a])
            part = src[a:b]
            for m in _ALL.finditer(part):
                line = src.count("\n", 0, a + m.start()) + 1
                print(f"{path.relative_to(ROOT)}:{line}: {m.group(0)} -> {_american(m.group(0))}")
                found += 1
            out.append(_american(part))
            pos = b
        out.append(src[pos:])
        if args.fix:
            new = "".join(out)
            if new != src:
                path.write_text(new, encoding="utf-8")
    if found and not args.fix:
        print(f"{found} British spellings (fix with: python scripts/american_spelling.py --fix)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
