"""Docs that run: every code block of README.md and docs/*.md is executed, in order per file, in a
temporary directory (a small collector of our own: the Markdown plugins we looked at run Python
blocks only, and ours are bash, Python and TOML side by side).

* ```python blocks run in one namespace per file (matplotlib draws off screen);
* ```bash blocks run line by line with the venv's bin first on PATH (``.venv/bin/`` means this
  interpreter's bin folder); a line must exit 0, or 1 for a ``poincare run`` whose summary reports a
  pair that is not ``ok`` (the documented exit status); no line may print a traceback;
* ```toml blocks must parse; one whose first line is ``# name.toml`` is written to that file for the
  blocks after it.

A block can be left out only by an HTML comment on the line before its fence,
``<!-- not run: reason -->``; the reason shows in the Markdown source and in this test's output.
"""
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FILES = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
FENCE = re.compile(r"^```(\w+)\s*$")
SKIP = re.compile(r"^<!--\s*not run:\s*(.+?)\s*-->\s*$")


def blocks(path):
    """[(language, code, first line number, reason not run or None)] of a Markdown file."""
    out, lines = [], path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m:
            skip = SKIP.match(lines[i - 1]) if i else None
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            out.append((m.group(1), "\n".join(lines[i + 1:j]), i + 2, skip.group(1) if skip else None))
            i = j
        i += 1
    return out


def _bash(line, cwd, env):
    cmd = line.replace(".venv/bin/", str(Path(sys.executable).parent) + "/")
    r = subprocess.run(["bash", "-c", cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=900)
    allowed = (0, 1) if re.search(r"poincare run\b", cmd) else (0,)
    assert r.returncode in allowed and "Traceback" not in r.stderr, \
        f"`{line}` exited {r.returncode}:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}"


@pytest.mark.slow
@pytest.mark.parametrize("path", [p for p in FILES if blocks(p)], ids=lambda p: p.name)
def test_every_code_block_runs(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    env = dict(os.environ, PATH=str(Path(sys.executable).parent) + os.pathsep + os.environ.get("PATH", ""),
               MPLBACKEND="Agg")
    namespace = {"__name__": "__docs__"}
    skipped = []
    for lang, code, line, reason in blocks(path):
        where = f"{path.name}:{line}"
        if reason:
            skipped.append(f"{where} ({reason})")
            continue
        if lang == "python":
            exec(compile(code, where, "exec"), namespace)
        elif lang == "bash":
            for ln in code.splitlines():
                cmd = ln.split(" #")[0].strip() if not ln.lstrip().startswith("#") else ""
                if cmd:
                    _bash(cmd, tmp_path, env)
        elif lang == "toml":
            tomllib.loads(code)
            first = code.splitlines()[0] if code else ""
            m = re.match(r"#\s*([\w.-]+\.toml)\s*$", first)
            if m:
                (tmp_path / m.group(1)).write_text(code + "\n")
        else:
            pytest.fail(f"{where}: a ```{lang} block; the collector runs python, bash and toml")
    if skipped:
        print(f"{path.name}: not run: " + "; ".join(skipped))


def test_the_collector_reads_fences_and_reasons(tmp_path):
    md = tmp_path / "x.md"
    md.write_text("text\n<!-- not run: slow -->\n```bash\nsleep 100\n```\n\n```python\nx = 1\n```\n")
    assert blocks(md) == [("bash", "sleep 100", 4, "slow"), ("python", "x = 1", 8, None)]


def test_the_example_notebook_runs(tmp_path):
    """docs/tour.ipynb executed by a Jupyter kernel (nbclient), in a temporary directory: every cell
    runs, and its audit of RK4 on the point vortices finds the map not symplectic."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.read(ROOT / "docs" / "tour.ipynb", as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")   # stored without outputs
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    last = nb.cells[-1].outputs[-1]["data"]["text/plain"]
    assert last == "'not symplectic'"
    said = [o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.get("name") == "stderr"]
    assert not any("Warning" in x for x in said), said      # e.g. tqdm's "IProgress not found" (no ipywidgets)
    widgets = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
               if "application/vnd.jupyter.widget-view+json" in o.get("data", {})]
    assert widgets, "the run's progress bar is not a widget"
    assert (tmp_path / "tour.h5").exists()


def test_the_api_reference_builds_without_warnings(tmp_path):
    """docs/api: mkdocs + mkdocstrings from the docstrings, --strict (a warning fails the build);
    every page documents objects."""
    exe = Path(sys.executable).parent / "mkdocs"
    if not exe.exists():
        pytest.fail("mkdocs is not installed: pip install \".[test]\" installs it (pyproject.toml's test extra)")
    r = subprocess.run([str(exe), "build", "--strict", "-f", str(ROOT / "docs/api/mkdocs.yml"), "-d", str(tmp_path)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    for page in ("integrators", "service", "audit", "invariants"):
        assert (tmp_path / f"{page}.html").read_text().count("doc-object") >= 5, page
