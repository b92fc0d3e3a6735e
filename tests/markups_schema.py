#!/usr/bin/python3
"""markups_schema.py — the markups files written by test_markups (src/io/markups.c)
hold what 3D Slicer's markups schema v1.0.3 requires and its reader uses,
with the JSON types the schema names (docs/anatomy.md, "Markups").

Top level: "@schema" (a string naming markups-schema-v1.0.3) and "markups",
an array of one object with "type" (one of the schema's enum: Curve for
electrode.mrk.json, Fiducial for targets.mrk.json), "coordinateSystem" RAS,
"coordinateUnits" mm, and "controlPoints", each with "id", "label",
"description", "associatedNodeID" (strings), "position" (3 numbers written
with a decimal point, as Slicer writes doubles), "orientation" (9 numbers),
"selected", "locked", "visibility" (booleans) and "positionStatus" "defined";
"display" an object whose colours are 3 numbers in [0, 1]. The values are
those test_markups wrote: the targets' labels (a quote, a comma and a
non-ASCII letter kept) and positions in mm (its metres times 1000).
Argument: the scratch folder. Silent on success; one line per failure, exit 1.
"""
import json
import os
import sys

DIR = sys.argv[1]
failures = []


def check(cond, msg):
    if not cond:
        failures.append(msg)
        print("FAIL:", msg, file=sys.stderr)


def number_list(v, n):
    return isinstance(v, list) and len(v) == n and all(isinstance(x, float) for x in v)


def check_file(name, kind, labels, positions):
    path = os.path.join(DIR, name)
    with open(path, encoding="utf-8") as f:
        doc = json.load(f)
    check(isinstance(doc.get("@schema"), str) and "markups-schema-v1.0.3.json" in doc["@schema"],
          "%s: @schema %r" % (name, doc.get("@schema")))
    check(isinstance(doc.get("markups"), list) and len(doc["markups"]) == 1, "%s: markups" % name)
    m = doc["markups"][0]
    enum = ["Fiducial", "Line", "Angle", "Curve", "ClosedCurve", "Plane", "ROI"]
    check(m.get("type") == kind and kind in enum, "%s: type %r" % (name, m.get("type")))
    check(m.get("coordinateSystem") == "RAS", "%s: coordinateSystem" % name)
    check(m.get("coordinateUnits") == "mm", "%s: coordinateUnits" % name)
    check(isinstance(m.get("locked"), bool) and isinstance(m.get("labelFormat"), str), "%s: locked, labelFormat" % name)
    cps = m.get("controlPoints")
    check(isinstance(cps, list) and len(cps) == len(positions), "%s: %d control points" % (name, len(cps or [])))
    for i, cp in enumerate(cps or []):
        where = "%s: controlPoints[%d]" % (name, i)
        for key in ("id", "label", "description", "associatedNodeID"):
            check(isinstance(cp.get(key), str), "%s: %s is not a string" % (where, key))
        check(number_list(cp.get("position"), 3), "%s: position %r" % (where, cp.get("position")))
        check(number_list(cp.get("orientation"), 9), "%s: orientation" % where)
        for key in ("selected", "locked", "visibility"):
            check(isinstance(cp.get(key), bool), "%s: %s is not a boolean" % (where, key))
        check(cp.get("positionStatus") == "defined", "%s: positionStatus" % where)
        check(cp.get("label") == labels[i], "%s: label %r, expected %r" % (where, cp.get("label"), labels[i]))
        if number_list(cp.get("position"), 3):
            err = max(abs(a - b) for a, b in zip(cp["position"], positions[i]))
            check(err < 1e-9, "%s: position %s, expected %s mm" % (where, cp["position"], positions[i]))
    d = m.get("display")
    check(isinstance(d, dict), "%s: display" % name)
    for key in ("color", "selectedColor"):
        c = (d or {}).get(key)
        check(number_list(c, 3) and all(0 <= x <= 1 for x in c), "%s: display.%s %r" % (name, key, c))


def main():
    entry, tip = [31.0, 20.5, 95.5], [12.5, -12.0, 2.0]
    axis = [[e + (t - e) * i / 4.0 for e, t in zip(entry, tip)] for i in range(5)]
    check_file("electrode.mrk.json", "Curve", ["electrode-%d" % (i + 1) for i in range(5)], axis)
    check_file("targets.mrk.json", "Fiducial",
               ["STN_R", 'GPi "left", ventral', "Zona incerta \u00e9"],
               [[12.3, -45.6, 78.9], [-11.0, 0.0, 1e-6], [100.0, 200.0, -300.0]])
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
