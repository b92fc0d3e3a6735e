#!/usr/bin/env python3
"""make_templates — write the refinement templates templates/*.tmpl.

Every template shipped with needlehex is a tensor-product subdivision of the
parent cube [-1, 1]^3: one sorted list of breakpoints per axis, a node at
every combination, a child between every pair of consecutive breakpoints.

    hex2    breakpoints {-1, 0, 1} on every axis            27 nodes,  8 children
    hex3    {-1, -1/3, 1/3, 1}                              64 nodes, 27 children
    hex4    {-1, -1/2, 0, 1/2, 1}                          125 nodes, 64 children
    graded  x: {-1, 0, 1/2, 1}, y, z: {-1, 0, 1}            36 nodes, 12 children
            (finer towards the +x face)

Nodes are numbered x fastest (i + nx (j + ny k)), as the initial grid of the
mesh is; each child lists its 8 nodes in VTK hexahedron order. Breakpoint i
of n is (2 i - n) / n, so the lists are symmetric about 0, and coordinates
are written with repr(), the shortest text that reads back to the same
double: -1/3 is the double nearest -1/3 on every machine.

The format is described in templates/README.md. Run from anywhere:

    python3 tools/make_templates.py            # writes into <repo>/templates
    python3 tools/make_templates.py --check    # exit 1 if a file would change
"""
import os
import sys

# Natural-coordinate signs of the 8 nodes of a hexahedron, VTK order
# (the table in src/mesh/mesh.h).
CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
           (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]


def regular(n):
    """n + 1 equally spaced breakpoints on [-1, 1], endpoints exact."""
    return [(2 * i - n) / n for i in range(n + 1)]


def fmt(v):
    """repr(v), the shortest text that reads back to v, without a trailing .0."""
    text = repr(v + 0.0)  # + 0.0 turns -0.0 into 0.0
    return text[:-2] if text.endswith(".0") else text


def tensor(name, comment, xs, ys, zs):
    """The text of the tensor-product template with breakpoints xs, ys, zs."""
    nx, ny, nz = len(xs), len(ys), len(zs)
    nodes = [(xs[i], ys[j], zs[k]) for k in range(nz) for j in range(ny) for i in range(nx)]

    def index(i, j, k):
        return i + nx * (j + ny * k)

    cells = []
    for k in range(nz - 1):
        for j in range(ny - 1):
            for i in range(nx - 1):
                cells.append([index(i + a, j + b, k + c) for a, b, c in CORNERS])
    lines = ["# %s" % line if line else "#" for line in comment]
    lines += ["# Written by tools/make_templates.py; do not edit by hand.",
              "template %s" % name,
              "nodes %d" % len(nodes)]
    lines += ["%s %s %s" % tuple(fmt(v) for v in p) for p in nodes]
    lines.append("cells %d" % len(cells))
    lines += [" ".join(str(v) for v in c) for c in cells]
    return "\n".join(lines) + "\n"


def templates():
    out = {}
    for n in (2, 3, 4):
        b = regular(n)
        out["hex%d" % n] = tensor(
            "hex%d" % n,
            ["hex%d: regular %dx%dx%d subdivision of the parent cube." % (n, n, n, n),
             "Breakpoints on every axis: %s." % ", ".join(fmt(v) for v in b)],
            b, b, b)
    xs, yz = [-1.0, 0.0, 0.5, 1.0], [-1.0, 0.0, 1.0]
    out["graded"] = tensor(
        "graded",
        ["graded: finer towards the +x face of the parent.",
         "Breakpoints x: -1, 0, 0.5, 1; y and z: -1, 0, 1 (3 x 2 x 2 children).",
         "The face x = -1 carries a 3x3 grid of nodes, the face x = +1 as well,",
         "the faces y = +-1 and z = +-1 a 4x3 grid."],
        xs, yz, yz)
    return out


def main(argv):
    check = "--check" in argv[1:]
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    folder = os.path.join(root, "templates")
    os.makedirs(folder, exist_ok=True)
    stale = 0
    for name, text in templates().items():
        path = os.path.join(folder, name + ".tmpl")
        old = None
        if os.path.exists(path):
            with open(path) as f:
                old = f.read()
        if check:
            if old != text:
                print("%s is not what tools/make_templates.py writes" % path, file=sys.stderr)
                stale += 1
        elif old != text:
            with open(path, "w") as f:
                f.write(text)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
