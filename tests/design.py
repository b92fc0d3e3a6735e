"""docs/design.md against the code (tests/design.cmake).

  design.py layering   The module order: reads the line
                       `layering: core < scene < ... < sim` and fails if any
                       src/<module>/*.[ch] includes "<other>/..." for a module
                       above its own, or any header of another module but its
                       public "<other>/<other>.h"; also if a directory of src/
                       is missing from the order or the order names a module
                       that does not exist. Then the file orders within a
                       module: a line `files <module>: a, b < c < d` fails if
                       a file calls a function (not static) defined in a file
                       of its own group or a later one (no circles), or if a
                       .c file of the module is missing from the line.
  design.py refs       The page's references: every `nh_...` name is defined
                       (a function, a type or a table) somewhere in src/, every
                       `src/...` or `<module>/<file>.[ch]` path exists, and in
                       a "`<module>/<file>.c`: `nh_a`, `nh_b`" reference each
                       function is defined in that very file; every
                       `tools/<file>.py` exists, and in a "`tools/<file>.py`:
                       `a`, `b`" reference (the tools' one home for each
                       helper) each function is defined (`def` at the top
                       level) in that file and in no other tools/*.py.

  design.py alloc      Every allocation goes through the checked allocator
                       (nh_calloc / nh_grow / nh_realloc, src/core/error.c):
                       fails on a call of malloc, calloc or realloc anywhere
                       else in src/ (comments and strings ignored).

Each first checks the checker on synthetic input (an upward include, a
private one, a downward one; a page with a wrong file and an unknown name;
tools with a helper defined twice, one missing and a missing file).
Silent on success; on failure one line per offence.
"""
import glob
import os
import re
import sys

ROOT = os.environ.get("NH_SOURCE_DIR") or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DESIGN = os.path.join(ROOT, "docs", "design.md")

# ---- layering ----
INCLUDE = re.compile(r'^\s*#\s*include\s+"([A-Za-z0-9_]+)/([^"]+)"')


def read_order(design):
    lines = [l.strip() for l in open(design, encoding="utf-8") if l.strip().startswith("layering:")]
    if len(lines) != 1:
        sys.exit(f"{design}: expected exactly one line 'layering: a < b < ...', found {len(lines)}")
    mods = [m.strip() for m in lines[0][len("layering:"):].split("<")]
    if not all(re.fullmatch(r"[a-z0-9_]+", m) for m in mods) or len(set(mods)) != len(mods):
        sys.exit(f"{design}: bad layering line: {lines[0]!r}")
    return {m: i for i, m in enumerate(mods)}


def violations(rank, files):
    """files: iterable of (module, path, lines). One message per offending include."""
    out = []
    for mod, path, lines in files:
        for n, line in enumerate(lines, 1):
            m = INCLUDE.match(line)
            if not m:
                continue
            dep = m.group(1)
            if dep not in rank:
                out.append(f"{path}:{n}: includes \"{dep}/...\", a module not in the layering line")
            elif rank[dep] > rank[mod]:
                out.append(f"{path}:{n}: {line.strip()}: {mod} (rank {rank[mod]}) includes "
                           f"{dep} (rank {rank[dep]}), which is above it")
            elif dep != mod and m.group(2) != dep + ".h":
                out.append(f"{path}:{n}: {line.strip()}: a private header of {dep}; "
                           f"other modules include only {dep}/{dep}.h")
    return out


def check_layering():
    rank = read_order(DESIGN)
    errors = []

    # The checker itself: an upward include must be caught, a downward one not.
    low, high = min(rank, key=rank.get), max(rank, key=rank.get)
    if not violations(rank, [(low, "synthetic.c", [f'#include "{high}/{high}.h"'])]):
        errors.append(f"self-check: {low} including {high} was not reported")
    if violations(rank, [(high, "synthetic.c", [f'#include "{low}/{low}.h"'])]):
        errors.append(f"self-check: {high} including {low} was reported")
    if not violations(rank, [(high, "synthetic.c", [f'#include "{low}/{low}_impl.h"'])]):
        errors.append(f"self-check: {high} including {low}'s private header was not reported")

    src = os.path.join(ROOT, "src")
    dirs = sorted(d for d in os.listdir(src) if os.path.isdir(os.path.join(src, d)))
    for d in dirs:
        if d not in rank:
            errors.append(f"src/{d}/: module missing from the layering line of docs/design.md")
    for m in rank:
        if m not in dirs:
            errors.append(f"docs/design.md: layering names {m}, which has no src/{m}/")
    files = []
    for d in dirs:
        if d not in rank:
            continue
        for f in sorted(os.listdir(os.path.join(src, d))):
            if f.endswith((".c", ".h")):
                p = os.path.join(src, d, f)
                files.append((d, os.path.relpath(p, ROOT), open(p, encoding="utf-8").read().splitlines()))
    if not files:
        errors.append("no source files found under src/")
    errors += violations(rank, files)
    errors += check_file_orders()
    return errors


# ---- file order within a module ----
FILES = re.compile(r"^files ([a-z0-9_]+): (.+)$", re.M)
CALL = re.compile(r"\b(nh_\w+)\s*\(")


def strip_c(text):
    """C text without comments and string literals (names there are no calls)."""
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    return re.sub(r'"(?:\\.|[^"\\\n])*"', '""', text)


def call_violations(rank, sources):
    """rank: file -> group; sources: file -> C text. A file may call only the
    external functions of files in earlier groups. One message per call."""
    owner = {}
    for f, text in sources.items():
        for m in DEF.finditer(text):
            if not text[m.start():m.end()].lstrip().startswith(("return", "if", "else", "static")):
                owner[m.group(1)] = f
    out = []
    for f, text in sorted(sources.items()):
        for name in sorted(set(CALL.findall(strip_c(text)))):
            g = owner.get(name)
            if g and g != f and rank[g] >= rank[f]:
                out.append(f"{f} calls {name} ({g}), which is not before it in the file order")
    return out


def check_file_orders():
    errors = []
    # The checker itself: a call up the order and one within a group must be
    # caught, a call down it not; a comment or a string is no call.
    a = "int nh_a(void) { return nh_b(); }"
    b = 'int nh_b(void) { /* nh_a() */ return puts("nh_a()"); }'
    if not call_violations({"a.c": 0, "b.c": 1}, {"a.c": a, "b.c": b}):
        errors.append("self-check: a call up the file order was not reported")
    if not call_violations({"a.c": 0, "b.c": 0}, {"a.c": a, "b.c": b}):
        errors.append("self-check: a call within a group was not reported")
    if call_violations({"a.c": 1, "b.c": 0}, {"a.c": a, "b.c": b}):
        errors.append("self-check: a call down the file order (or a comment) was reported")
    page = open(DESIGN, encoding="utf-8").read()
    for m in FILES.finditer(page):
        mod = m.group(1)
        rank = {}
        for i, group in enumerate(m.group(2).split("<")):
            for name in group.split(","):
                rank[name.strip() + ".c"] = i
        paths = glob.glob(os.path.join(ROOT, "src", mod, "*.c"))
        if not paths:
            errors.append(f"docs/design.md: files {mod}: no src/{mod}/*.c")
        sources = {os.path.basename(p): open(p, encoding="utf-8").read() for p in paths}
        for f in sorted(set(sources) - set(rank)):
            errors.append(f"src/{mod}/{f}: missing from the line 'files {mod}: ...' of docs/design.md")
        for f in sorted(set(rank) - set(sources)):
            errors.append(f"docs/design.md: files {mod}: names {f}, which is not in src/{mod}/")
        known = {f: t for f, t in sources.items() if f in rank}
        errors += [f"src/{mod}/" + e for e in call_violations(rank, known)]
    return errors


# ---- references ----
# A definition: a function (return type, name, parenthesis, not a call
# statement), a typedef'd name, or a const table, at the start of a line.
DEF = re.compile(r"^(?:[A-Za-z_][\w \t*]*?[\s*])(nh_\w+)\s*[(\[]", re.M)
TYPEDEF = re.compile(r"\}\s*(nh_\w+)\s*;|typedef\s+[\w\s*]+?\b(nh_\w+)\s*;")
FILE_FNS = re.compile(r"`((?:src/)?[a-z0-9_]+/[a-z0-9_]+\.[ch])`: ((?:`nh_\w+`(?:, )?)+)")
PATH = re.compile(r"`((?:src/)?[a-z0-9_]+/[a-z0-9_]+\.[ch])`")


def definitions(root):
    defs = {}
    for f in glob.glob(os.path.join(root, "src", "**", "*.[ch]"), recursive=True):
        rel = os.path.relpath(f, root)
        text = open(f, encoding="utf-8").read()
        for m in DEF.finditer(text):
            head = text[m.start():m.end()]
            if head.lstrip().startswith(("return", "if", "else")):
                continue
            defs.setdefault(m.group(1), set()).add(rel)
        for m in TYPEDEF.finditer(text):
            defs.setdefault(m.group(1) or m.group(2), set()).add(rel)
    return defs


def stale(page, defs, exists):
    out = []
    for name in sorted(set(re.findall(r"\bnh_\w+", page))):
        if name not in defs:
            out.append(f"{name}: defined nowhere in src/")
    for p in sorted(set(PATH.findall(page))):
        q = p if p.startswith("src/") else "src/" + p
        if not exists(q):
            out.append(f"{p}: no such file {q}")
    for m in FILE_FNS.finditer(page):
        q = m.group(1) if m.group(1).startswith("src/") else "src/" + m.group(1)
        for fn in re.findall(r"nh_\w+", m.group(2)):
            if fn in defs and q not in defs[fn]:
                out.append(f"{m.group(1)}: {fn} is defined in {', '.join(sorted(defs[fn]))}, not here")
    return out


TOOL_PATH = re.compile(r"`(tools/[a-z0-9_]+\.py)`")
TOOL_FNS = re.compile(r"`(tools/[a-z0-9_]+\.py)`: ((?:`\w+`(?:, )?)+)")
PY_DEF = re.compile(r"^def (\w+)\(", re.M)


def stale_tools(page, tools):
    """tools: {path: text} of tools/*.py. The tools/*.py paths the page names that do not exist,
    and the functions of a "`tools/x.py`: `f`, `g`" reference not defined in x.py or defined
    in another tool too."""
    out = [f"{p}: no such file" for p in sorted(set(TOOL_PATH.findall(page))) if p not in tools]
    defs = {}
    for path, text in tools.items():
        for fn in PY_DEF.findall(text):
            defs.setdefault(fn, set()).add(path)
    for m in TOOL_FNS.finditer(page):
        home = m.group(1)
        for fn in re.findall(r"`(\w+)`", m.group(2)):
            where = defs.get(fn, set())
            if home not in where:
                out.append(f"{home}: {fn} is not defined there")
            elif len(where) > 1:
                out.append(f"{fn}: its home is {home}, defined again in "
                           f"{', '.join(sorted(where - {home}))}")
    return out


def check_refs():
    defs = definitions(ROOT)
    exists = lambda rel: os.path.exists(os.path.join(ROOT, rel))
    errors = []
    if "nh_sim_step" not in defs or "src/sim/sim.c" not in defs["nh_sim_step"]:
        errors.append("self-check: nh_sim_step not found in src/sim/sim.c")
    fake = "`sim/sim.c`: `nh_mcp_solve` and `nh_no_such_function` in `sim/nothing.c`"
    if len(stale(fake, defs, exists)) != 3:
        errors.append(f"self-check: the synthetic page gave {stale(fake, defs, exists)}")
    page = open(DESIGN, encoding="utf-8").read()
    errors += stale(page, defs, exists)
    fake_tools = {"tools/a.py": "def f(x):\n    pass\n", "tools/b.py": "def f(y):\n    def g():\n"}
    fake = "`tools/a.py`: `f`, `g`; `tools/c.py`"  # f twice, g not in a.py (nested in b), no c.py
    if len(stale_tools(fake, fake_tools)) != 3:
        errors.append(f"self-check: the synthetic tools gave {stale_tools(fake, fake_tools)}")
    tools = {os.path.relpath(f, ROOT): open(f, encoding="utf-8").read()
             for f in glob.glob(os.path.join(ROOT, "tools", "*.py"))}
    errors += stale_tools(page, tools)
    return errors


# ---- allocation ----
RAW_ALLOC = re.compile(r"(?<![\w.>])(malloc|calloc|realloc)\s*\(")
ALLOCATOR = "src/core/error.c"
# Files still converted by another branch of wave 6 (contact/, fem/tissue.c and
# sim/ belong to other helpers); an entry without a raw call left fails, so the
# list only shrinks.


def raw_allocs(sources):
    """sources: path -> C text. One message per raw call outside the allocator."""
    out = []
    for path, text in sorted(sources.items()):
        if path == ALLOCATOR:
            continue
        for n, line in enumerate(strip_c(text).split("\n"), 1):
            for m in RAW_ALLOC.finditer(line):
                out.append(f"{path}:{n}: {m.group(1)}() outside the checked allocator")
    return out


def check_alloc():
    fake = {"src/a/x.c": "p = malloc(4); /* calloc(1, 2) */ q = nh_calloc(1, 2); s.realloc(3);\n"
                         "r = realloc (p, 8);\n const char *t = \"malloc(9)\";",
            ALLOCATOR: "void *p = calloc(n, size);"}
    got = raw_allocs(fake)
    errors = []
    if [g.split(":")[1] for g in got] != ["1", "2"]:
        errors.append(f"self-check: the synthetic sources gave {got}")
    sources = {os.path.relpath(f, ROOT): open(f, encoding="utf-8").read()
               for f in glob.glob(os.path.join(ROOT, "src", "**", "*.[ch]"), recursive=True)}
    if ALLOCATOR not in sources or not RAW_ALLOC.search(sources[ALLOCATOR]):
        errors.append(f"self-check: {ALLOCATOR} holds no allocation")
    found = raw_allocs(sources)
    errors += found
    return errors


def main():
    checks = {"alloc": (check_alloc, "raw allocations outside src/core/error.c"),
              "layering": (check_layering, "layering (docs/design.md) violated"),
              "refs": (check_refs, "docs/design.md has stale references")}
    if len(sys.argv) != 2 or sys.argv[1] not in checks:
        sys.exit("usage: design.py layering|refs|alloc")
    check, title = checks[sys.argv[1]]
    errors = check()
    if errors:
        print(title + ":", file=sys.stderr)
        for e in errors:
            print("  " + e, file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
