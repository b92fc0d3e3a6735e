#!/usr/bin/env python3
"""bad_input — every bad scene makes `needlehex check` fail the same way.

For each fixture in tests/bad/ (and each bad --set on the valid
tests/bad/set_base.yaml) run

    $NH_BINARY check FILE [--set K=V ...]

and require: exit status 2; stderr exactly one non-empty line
"needlehex: <message>"; the message names the place (the fixture's file
name and ":LINE:", or "--set:K:") and the dotted key (" KEY:"); no sanitizer
report. The expected line and key of each case were written by hand from the
fixture's text (each fixture says in its first comment what it contains), not
copied from a run. A valid scene must pass `check` with status 0 and an
empty stderr. Bad command lines (COMMAND_LINES: an option where a value is
expected, a missing value, an unknown option) exit 2 with one line naming
the option and the command's usage line, and write nothing.

Every command (bad, valid, command line) must end within 10 s of wall time
and 600 MB of peak memory (the child's ru_maxrss from wait4); the count, the
slowest and the largest are printed in one line (the campaign's record,
docs/reliability.md), the rest only on failure. With NH_SANITIZED=1 (the
ASan + UBSan build, 5-10 times slower: a valid label image's check takes
26 s) the limits are printed, not asserted.

Environment: NH_BINARY (the needlehex executable), NH_SOURCE_DIR (the source
tree). Silent on success; prints every failing case and exits 1 otherwise.
"""
import os
import resource
import subprocess
import sys
import tempfile
import time

# (fixture, overrides, expected line or "--set:K", expected dotted key or None)
CASES = [
    ("malformed.yaml", [], 6, None),
    ("unknown_key.yaml", [], 7, "tissue.grids"),
    ("wrong_type.yaml", [], 9, "tissue.grid.1"),
    ("missing_tissue.yaml", [], 3, "tissue"),
    ("incompressible.yaml", [], 9, "tissue.material.poisson"),
    ("formulation.yaml", [], 9, "tissue.material.formulation"),
    ("young_zero.yaml", [], 8, "tissue.material.young"),
    ("zero_cells.yaml", [], 6, "tissue.grid.2"),
    ("end_and_steps.yaml", [], 6, "time.steps"),
    ("box_min_max.yaml", [], 7, "tissue.domain.box.max"),
    ("duplicate_key.yaml", [], 8, "tissue.material"),
    ("alias.yaml", [], 5, "tissue.domain.box.min"),
    ("mask_missing_file.yaml", [], 5, "tissue.domain.mask.file"),
    ("two_documents.yaml", [], 7, None),
    # Detected by the simulator (no node in the region), not by the scene
    # module: it reports the region's `where`, "FILE:11: tissue.fixed.0".
    ("region_no_node.yaml", [], 11, "tissue.fixed.0"),
    # Regions: no shape, two shapes, a negative sphere radius, a cylinder
    # without an axis; a brain of zero height; a probe in the brain's
    # bounding box but outside the brain (reported by the simulator).
    ("region_no_shape.yaml", [], 10, "tissue.fixed.0"),
    ("region_two_shapes.yaml", [], 12, "tissue.loads.0.cylinder"),
    ("brain_region_no_tissue.yaml", [], 11, "tissue.fixed.0"),
    ("region_sphere_radius.yaml", [], 12, "tissue.fixed.0.sphere.radius"),
    ("region_cylinder_axis.yaml", [], 11, "tissue.fixed.0.cylinder.end"),
    ("brain_size.yaml", [], 6, "tissue.domain.brain.size.2"),
    ("brain_probe_outside.yaml", [], 11, "probes.0"),
    # A tool whose tip starts inside the brain; one that passes in front of it.
    ("brain_tool_inside.yaml", [], 11, "tools.0"),
    ("brain_tool_misses.yaml", [], 12, "tools.0"),
    # A key the schema does not have, given by the second override.
    ("set_base.yaml", ["tissue.grid=[8,4,4]", "tissue.material.stiffnes=3"], "--set:2",
     "tissue.material.stiffnes"),
    # An index beyond the list (tissue.fixed has 1 entry).
    ("set_base.yaml", ["tissue.fixed.3.box.min=[0,0,0]"], "--set:1", "tissue.fixed.3"),
    # A wrong type given by an override.
    ("set_base.yaml", ["tissue.grid=[16,x,8]"], "--set:1", "tissue.grid.1"),
    ("set_base.yaml", ["solver.refactor=sometimes"], "--set:1", "solver.refactor"),
    ("set_base.yaml", ["solver.lazy_rotation=-1e-3"], "--set:1", "solver.lazy_rotation"),
    # An override that makes the file's time.end conflict.
    ("set_base.yaml", ["time.end=1", "time.steps=3"], "--set:2", "time.steps"),
    # adapt: a template name without a file, a theta outside (0, 1), theta
    # with the dorfler strategy, a template path relative to the scene's
    # folder that holds no such file; the same errors from overrides.
    ("adapt_unknown_template.yaml", [], 11, "adapt.template"),
    ("adapt_theta.yaml", [], 10, "adapt.marking.theta"),
    ("adapt_theta_dorfler.yaml", [], 9, "adapt.marking.theta"),
    ("adapt_template_path.yaml", [], 9, "adapt.template"),
    ("set_base.yaml", ["adapt.template=hex9"], "--set:1", "adapt.template"),
    ("set_base.yaml", ["adapt.every=2", "adapt.marking.theta=1.5"], "--set:2",
     "adapt.marking.theta"),
    ("set_base.yaml", ["adapt.hanging=both"], "--set:1", "adapt.hanging"),
    # adapt.resolve_tip with the spr estimator (the default), and not a boolean.
    ("set_base.yaml", ["adapt.resolve_tip=false"], "--set:1", "adapt.resolve_tip"),
    # adapt.local_dual with the spr estimator, and not a boolean.
    ("set_base.yaml", ["adapt.local_dual=true"], "--set:1", "adapt.local_dual"),
    ("set_base.yaml", ["adapt.estimator=goal", "adapt.local_dual=1"], "--set:2",
     "adapt.local_dual"),
    ("set_base.yaml", ["adapt.estimator=goal", "adapt.resolve_tip=2"], "--set:2",
     "adapt.resolve_tip"),
    # adapt.marking.goals: spr, with dorfler, with the combined dual, a word it does not know.
    ("set_base.yaml", ["adapt.marking.goals=each"], "--set:1", "adapt.marking.goals"),
    ("set_base.yaml", ["adapt.estimator=goal", "adapt.marking.strategy=dorfler",
                       "adapt.marking.goals=each"], "--set:3", "adapt.marking.goals"),
    ("set_base.yaml", ["adapt.estimator=goal", "adapt.marking.goals=each",
                       "adapt.separate_every=2"], "--set:3", "adapt.separate_every"),
    ("set_base.yaml", ["adapt.estimator=goal", "adapt.marking.goals=all"], "--set:2",
     "adapt.marking.goals"),
    # adapt.marking.goal_leaves: with spr.
    ("set_base.yaml", ["adapt.marking.goal_leaves=true"], "--set:1", "adapt.marking.goal_leaves"),
    ("set_base.yaml", ["adapt.estimator=goal", "adapt.marking.goals=each",
                       "adapt.coarsen={fraction: 0.1}"], "--set:3", "adapt.coarsen"),
    ("set_base.yaml", ["tissue.material.formulation=[bbar]"], "--set:1",
     "tissue.material.formulation"),
    # tools and targets: an unknown key, a missing length, a negative radius,
    # a wall of no thickness, a zero direction, motion times not increasing, a
    # host that does not exist, release without a host, a name given twice,
    # a target naming no tool, an incompressible tool; then the same kind of
    # errors from overrides of the valid tools_base.yaml.
    ("tool_unknown_key.yaml", [], 10, "tools.0.lenght"),
    ("tool_missing_length.yaml", [], 8, "tools.0.length"),
    ("tool_negative_radius.yaml", [], 10, "tools.0.radius"),
    ("tool_inner_radius.yaml", [], 11, "tools.0.inner_radius"),
    ("tool_zero_direction.yaml", [], 13, "tools.0.direction"),
    ("tool_motion_order.yaml", [], 16, "tools.0.motion.1.until"),
    ("tool_inside_unknown.yaml", [], 20, "tools.1.inside"),
    ("tool_release_without_inside.yaml", [], 14, "tools.0.release"),
    ("tool_duplicate_name.yaml", [], 14, "tools.1.name"),
    ("target_unknown_tool.yaml", [], 17, "targets.0.tool"),
    ("tool_poisson.yaml", [], 13, "tools.0.material.poisson"),
    ("tools_base.yaml", ["tools.0.interaction.friction=-0.1"], "--set:1",
     "tools.0.interaction.friction"),
    # a static friction coefficient below the kinetic one
    ("tools_base.yaml", ["tools.0.interaction.friction=0.2",
                         "tools.0.interaction.friction_static=0.1"], "--set:2",
     "tools.0.interaction.friction_static"),
    # bevel: the angle in [0, 90), required with the bevel; the side across the axis
    ("tools_base.yaml", ["tools.0.bevel.angle=90"], "--set:1", "tools.0.bevel.angle"),
    ("tools_base.yaml", ["tools.0.bevel.toward=[0,1,0]"], "--set:1", "tools.0.bevel.angle"),
    ("tools_base.yaml", ["tools.0.bevel.angle=10", "tools.0.bevel.toward=[2,0,0]"], "--set:2",
     "tools.0.bevel.toward"),
    ("tools_base.yaml", ["tools.0.motion.0.spin=fast"], "--set:1", "tools.0.motion.0.spin"),
    ("tools_base.yaml", ["tools.0.radius=0.001", "tools.1.inside=electrode"], "--set:2",
     "tools.1.inside"),
    ("tools_base.yaml", ["tools.2.length=1"], "--set:1", "tools.2"),
    # a motion that pushes the 32 mm cannula 50 mm: its base would end inside the tissue
    ("tools_base.yaml", ["tools.0.motion=[{until: 1.0, speed: 0.05}]"], 9, "tools.0"),
    ("set_base.yaml", ["tools.0.length=1"], "--set:1", "tools.0"),
    # formulation is the tissue's: a tool's material does not take it
    ("tools_base.yaml", ["tools.0.material.formulation=bbar"], "--set:1",
     "tools.0.material.formulation"),
    # gravity with a schedule, tissue buoyancy, planned trajectories: a schedule
    # whose times go back, a fraction above 1, a target name that is not a
    # target, a target at the entry, base given with a trajectory, until:
    # target with speed 0 and past the planned depth, until: start without a
    # trajectory, release: target when the host has no until: target; then
    # the same kind of errors from overrides of the valid trajectory_base.yaml.
    ("gravity_schedule.yaml", [], 5, "gravity.schedule.1.0"),
    ("buoyancy_fraction.yaml", [], 7, "tissue.buoyancy.before"),
    ("buoyancy_level.yaml", [], 9, "tissue.buoyancy.level"),
    ("skull_box.yaml", [], 8, "tissue.skull"),
    ("trajectory_base.yaml", ["tissue.skull={gap: -0.001}"], "--set:1", "tissue.skull.gap"),
    ("trajectory_base.yaml", ["tissue.skull={gaps: 0}"], "--set:1", "tissue.skull.gaps"),
    ("trajectory_base.yaml", ["tissue.skull={gap: 0.001, rows: nodes}"], "--set:1",
     "tissue.skull.rows"),
    ("trajectory_base.yaml", ["tissue.buoyancy.level=[0, 1]"], "--set:1",
     "tissue.buoyancy.level"),
    # tractions: both a traction and a pressure; a region without boundary
    # (found by the simulator); neither, from an override
    ("traction_both.yaml", [], 10, "tissue.tractions.0.pressure"),
    # fixed: an unknown axis; a schedule without a displacement (override)
    ("fixed_axes.yaml", [], 10, "tissue.fixed.0.axes.1"),
    ("set_base.yaml", ["tissue.fixed.0.schedule=[[0, 0], [1, 1]]"], "--set:1",
     "tissue.fixed.0.schedule"),
    # fixed.N.refine: a size, > 0 (zero, negative, not a number)
    ("set_base.yaml", ["tissue.fixed.0.refine=0"], "--set:1", "tissue.fixed.0.refine"),
    ("set_base.yaml", ["tissue.fixed.0.refine=-0.001"], "--set:1", "tissue.fixed.0.refine"),
    ("set_base.yaml", ["tissue.fixed.0.refine=fine"], "--set:1", "tissue.fixed.0.refine"),
    ("traction_no_boundary.yaml", [], 11, "tissue.tractions.0"),
    ("traction_both.yaml", ["tissue.tractions.0={box: {min: [0, 0, 0], max: [1, 1, 1]}}"],
     "--set:1", "tissue.tractions.0"),
    ("trajectory_unknown_target.yaml", [], 12, "tools.0.trajectory.target"),
    ("trajectory_target_at_entry.yaml", [], 12, "tools.0.trajectory.target"),
    ("trajectory_with_base.yaml", [], 13, "tools.0.base"),
    ("until_target_speed.yaml", [], 14, "tools.0.motion.0.speed"),
    ("until_target_past.yaml", [], 15, "tools.0.motion.1.until"),
    ("until_without_trajectory.yaml", [], 16, "tools.0.motion.1.until"),
    ("release_target_no_plan.yaml", [], 21, "tools.1.release"),
    ("trajectory_base.yaml", ["tools.0.trajectory.target=GPi"], "--set:1",
     "tools.0.trajectory.target"),
    ("trajectory_base.yaml", ["tools.0.trajectory.standoff=0"], "--set:1",
     "tools.0.trajectory.standoff"),
    ("trajectory_base.yaml", ["tools.0.direction=[1,0,0]"], "--set:1", "tools.0.direction"),
    # until: target resolves to 2.018 s, so a following until of 2 s is out of order
    ("trajectory_base.yaml", ["tools.0.motion.1.until=2"], "--set:1", "tools.0.motion.1.until"),
    ("trajectory_base.yaml", ["tools.0.motion.2.speed=0.01"], "--set:1", "tools.0.motion.2.speed"),
    ("trajectory_base.yaml", ["tools.1.release=later"], "--set:1", "tools.1.release"),
    ("trajectory_base.yaml", ["tissue.buoyancy={before: 0.5}"], "--set:1", "tissue.buoyancy.after"),
    ("trajectory_base.yaml", ["gravity={vector: [0, 0, -9.81], ramp: 1}"], "--set:1",
     "gravity.ramp"),
    # Limits (refused before anything is allocated: see SIZE_CASES for the
    # time), a valid but degenerate box, raw control bytes in a key and in an
    # override (the message shows them escaped: checked for every case).
    ("limits_max_cells.yaml", [], 8, "tissue.grid"),
    ("box_elongated.yaml", [], 6, "tissue.domain.box"),
    ("control_bytes.yaml", [], 5, None),
    ("set_base.yaml", ["tissue.grid=[16,\x1b[31m,8]"], "--set:1", "tissue.grid"),
    ("set_base.yaml", ["limits.max_cells=0"], "--set:1", "limits.max_cells"),
    # limits.max_voxels: the label image's header (150 x 80 x 39 voxels) exceeds 100
    ("materials_negative_label.yaml", ["tissue.materials={2: {young: 1e6}}",
                                       "limits.max_voxels=100"], 7, "tissue.labels.file"),
    # A material's label: whole numbers >= 0 written in digits (not -2, 2.0, +2);
    # the same fixture with label 2 (held by the image) is valid (VALID).
    ("materials_negative_label.yaml", [], 10, "tissue.materials.-2"),
    ("materials_negative_label.yaml", ["tissue.materials={2.0: {young: 1e6}}"], "--set:1",
     "tissue.materials.2.0"),
    ("materials_negative_label.yaml", ["tissue.materials={+2: {young: 1e6}}"], "--set:1",
     "tissue.materials.+2"),
    # A tool shorter than its planned depth D = standoff + |aim - entry|: its
    # base would end past the entry point (D by hand: 0.022, 0.033 and
    # 0.005 + |STN - entry| = 0.025199 m against lengths 0.02, 0.032, 0.025).
    ("tool_shorter_than_depth.yaml", [], 11, "tools.0.length"),
    ("trajectory_base.yaml", ["tools.0.trajectory.aim=[0.031, 0.01, 0.01]"], 12,
     "tools.0.length"),
    ("trajectory_base.yaml", ["tools.1.length=0.025"], "--set:1", "tools.1.length"),
    # A negative label where a label is expected: in the mask's labels, a
    # fixed region, a load (the materials' keys: above).
    ("mask_negative_label.yaml", [], 6, "tissue.domain.mask.labels.1"),
    ("region_negative_label.yaml", [], 11, "tissue.fixed.1.label"),
    ("region_negative_label.yaml", ["tissue.fixed=[]",
                                    "tissue.loads=[{label: -3, force: [0, 0, 1]}]"], "--set:2",
     "tissue.loads.0.label"),
    ("region_negative_label.yaml", ["tissue.fixed=[]", "plan={obstacles: [{label: -1}]}"],
     "--set:2", "plan.obstacles.0.label"),
    # solver.newton where no step takes it: in static mode (Newton already);
    # in dynamic mode, with tools or without, it is valid (VALID).
    ("set_base.yaml", ["time.mode=static", "solver.newton={tolerance: 1e-9}"], "--set:2",
     "solver.newton"),
    # Numbers that become counts or sizes (issue 31's overflow audit): an int
    # that does not fit, a grid whose cells (2^31 - 1) or nodes (46341^2 x 2
    # x 3 dofs > 2^31) overflow an int even with max_cells raised, steps
    # beyond 1e7 given directly (was: "out of memory: timing table", exit 1)
    # or as end / step (1e302), a step outside [1e-9, 1e6] s (1e-300: ρ/Δt²
    # infinite, the run stood still and "succeeded"; 1e300: exit 1 at step
    # 1), 2^31 - 1 beam elements (was: n + 1 overflowed, a negative
    # allocation), a box whose cells overflow their aspect ratio.
    ("set_base.yaml", ["tissue.grid=[1e10,1,1]"], "--set:1", "tissue.grid.0"),
    ("set_base.yaml", ["tissue.grid=[2147483647,1,1]", "limits.max_cells=2147483647"], "--set:1",
     "tissue.grid"),
    ("set_base.yaml", ["tissue.grid=[46341,46341,1]", "limits.max_cells=2147483647"], "--set:1",
     "tissue.grid"),
    # cells within limits.max_cells, but 3 x 30001^2 x 3 unknowns beyond an int
    ("set_base.yaml", ["tissue.grid=[30000,30000,2]", "limits.max_cells=2147483647"], "--set:1",
     "tissue.grid"),
    ("set_base.yaml", ["limits.max_cells=99999999999"], "--set:1", "limits.max_cells"),
    ("set_base.yaml", ["time.steps=2147483647"], "--set:1", "time.steps"),
    ("set_base.yaml", ["time.steps=10000001"], "--set:1", "time.steps"),
    ("set_base.yaml", ["time.steps=99999999999"], "--set:1", "time.steps"),
    ("set_base.yaml", ["time.end=1e300"], "--set:1", "time.end"),
    ("set_base.yaml", ["time.step=1e-300"], "--set:1", "time.step"),
    ("set_base.yaml", ["time.step=1e-300", "time.end=1"], "--set:1", "time.step"),
    ("set_base.yaml", ["time.step=1e300"], "--set:1", "time.step"),
    ("set_base.yaml", ["tissue.domain.box.max=[1e300,1,1]"], 5, "tissue.domain.box"),
    ("tools_base.yaml", ["tools.0.elements=2147483647"], "--set:1", "tools.0.elements"),
    ("tools_base.yaml", ["tools.0.elements=100001"], "--set:1", "tools.0.elements"),
]

# Cases run with an environment of their own: (fixture, overrides, env,
# where, key). tissue.fixed.N.refine without an adapt section refines by
# hex2, so its template must be readable: with NH_TEMPLATES_DIR naming a
# folder that does not exist, the refine key is the one reported; the same
# fixture without the overrides (no refine key) needs no template and passes.
ENV_CASES = [
    ("set_base.yaml", ["tissue.fixed.0.refine=0.01"],
     {"NH_TEMPLATES_DIR": "/nonexistent-needlehex-templates"}, "--set:1",
     "tissue.fixed.0.refine"),
]

# Scenes that `needlehex plan` must refuse as `check` does, before any run.
PLAN_CASES = [("tool_shorter_than_depth.yaml", [], 11, "tools.0.length")]

# Sizes far beyond the machine: refused by `check` within 1 s, naming the
# grid and the estimated memory (the unchecked 400^3 grid took 35 s and
# 10.4 GB before failing to allocate).
SIZE_CASES = [("set_base.yaml", ["tissue.grid=[400,400,400]"], "--set:1", "tissue.grid"),
              ("set_base.yaml", ["tissue.grid=[200,200,200]"], "--set:1", "tissue.grid"),
              ("set_base.yaml", ["tissue.grid=[400,400,400]", "limits.max_cells=100000000"],
               "--set:1", "tissue.grid")]

# Scenes that must pass `check`.
# The adapt ones need the shipped templates (templates/hex2.tmpl, hex3.tmpl)
# found through the compiled-in templates folder.
VALID = [("set_base.yaml", []), ("set_base.yaml", ["tissue.damping.mass=0.5", "tissue.grid=[8,4,4]"]),
         ("set_base.yaml", ["adapt.marking.theta=0.5"]),
         ("set_base.yaml", ["adapt.template=hex3", "adapt.marking={strategy: dorfler, fraction: 0.4}",
                            "adapt.hanging=lagrange"]),
         ("tools_base.yaml", []),
         ("trajectory_base.yaml", []),
         ("trajectory_base.yaml", ["gravity=[0, 0, -9.81]", "tools.0.trajectory.standoff=0.001",
                                   "tools.1.release=1.5", "tissue.buoyancy.schedule=[]"]),
         ("tools_base.yaml", ["tools.0.interaction.friction=0.1", "tools.1.release=0.75",
                              "targets.0.tool=cannula"]),
         ("materials_negative_label.yaml", ["tissue.materials={2: {young: 2.0e6}}"]),
         # a run cut short before the cannula (2 mm standoff, 1 mm cells) meets the
         # tissue: the tool's reach is checked over its whole motion, not the run's
         ("trajectory_base.yaml", ["time.steps=1", "tissue.grid=[40, 20, 20]"]),
         # a tool exactly as long as its planned depth (0.022 m)
         ("tool_shorter_than_depth.yaml", ["tools.0.length=0.022"]),
         ("set_base.yaml", ["solver.newton={max_iterations: 3}"]),
         ("tools_base.yaml", ["solver.newton={max_iterations: 3}"]),
         ("mask_negative_label.yaml", ["tissue.domain.mask.labels=[1, 2]"]),
         # Counts at their bounds, and periods as large as an int: a step
         # count <= 1e7 keeps step + 1 and step % N far from overflow.
         ("set_base.yaml", ["time.steps=10000000", "output.every=2147483647",
                            "output.checkpoint=2147483647"]),
         ("set_base.yaml", ["time.step=1e-9"]), ("set_base.yaml", ["time.step=1e6"]),
         ("set_base.yaml", ["adapt.every=2147483647", "adapt.max_level=2147483647"]),
         ("tools_base.yaml", ["tools.0.elements=100000"])]

# Command lines (argv after the binary; SCENE is tests/bad/set_base.yaml),
# each refused with exit 2 and one line naming the option and holding the
# command's usage line: an option where a value is expected, a missing
# value, an unknown option. Run in an empty folder, which must stay empty
# (the run must not start writing into a folder named after an option).
COMMAND_LINES = [
    (["run", "SCENE", "--out", "--quiet"], "--out needs a value, got the option '--quiet'"),
    (["run", "SCENE", "--set", "--overwrite"], "--set needs a value, got the option '--overwrite'"),
    (["run", "SCENE", "--restart", "-q"], "--restart needs a value, got the option '-q'"),
    (["run", "SCENE", "--out"], "--out needs a value"),
    (["plan", "SCENE", "--tolerance", "--quiet"], "--tolerance needs a value, got the option"),
    (["check", "SCENE", "--frobnicate"], "unknown option '--frobnicate'"),
]

SANITIZER_WORDS = ("AddressSanitizer", "LeakSanitizer", "runtime error", "UndefinedBehaviorSanitizer")


MAX_SECONDS, MAX_MB = 10.0, 600.0
RECORD = []  # (seconds, MB, command) of every child


def measured(args, cwd=None, env=None):
    """Run args; (exit status or None if killed at 60 s, stdout, stderr),
    its wall time and peak memory recorded in RECORD and checked by main."""
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.monotonic()
        p = subprocess.Popen(args, stdout=out, stderr=err, cwd=cwd, text=True,
                             env=dict(os.environ, **env) if env else None)
        while True:
            pid, status, usage = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if time.monotonic() - start > 60:
                p.kill()
            time.sleep(0.002)
        seconds = time.monotonic() - start
        p.returncode = os.waitstatus_to_exitcode(status)
        RECORD.append((seconds, usage.ru_maxrss / 1024.0, " ".join(args)))
        out.seek(0), err.seek(0)
        rc = None if p.returncode == -9 else p.returncode
        return rc, out.read(), err.read() if rc is not None else "killed after 60 s"


def run(binary, path, overrides, command=("check",), env=None):
    args = [binary, command[0], path] + list(command[1:])
    for o in overrides:
        args += ["--set", o]
    rc, out, err = measured(args, env=env)
    return rc, out, err, args


def check_case(binary, bad_dir, fixture, overrides, where, key, command=("check",), env=None):
    path = os.path.join(bad_dir, fixture)
    problems = []
    if not os.path.isfile(path):
        return ["fixture %s does not exist" % path]
    status, _, err, args = run(binary, path, overrides, command, env)
    shown = " ".join(args)
    if status != 2:
        problems.append("exit status: expected 2, got %s" % status)
    for w in SANITIZER_WORDS:
        if w in err:
            problems.append("sanitizer report in stderr (%s)" % w)
    lines = err.split("\n")
    if not (len(lines) == 2 and lines[1] == "" and lines[0].strip()):
        problems.append("stderr: expected exactly one non-empty line, got %d line(s)"
                        % err.count("\n"))
    msg = lines[0]
    raw = [c for c in msg if ord(c) < 0x20 or ord(c) == 0x7f]
    if raw:
        problems.append("message: raw control bytes %r (they must be escaped)" % raw)
    if not msg.startswith("needlehex: "):
        problems.append("message: expected to start with 'needlehex: '")
    if isinstance(where, int):
        if fixture not in msg:
            problems.append("message: expected the file name %r" % fixture)
        if "%s:%d:" % (fixture, where) not in msg:
            problems.append("message: expected '%s:%d:' (file and line)" % (fixture, where))
    else:
        if where + ":" not in msg:
            problems.append("message: expected '%s:' (the override)" % where)
    if key is not None and (" %s:" % key) not in msg:
        problems.append("message: expected the key ' %s:'" % key)
    if problems:
        problems.insert(0, "%s\n    stderr: %r" % (shown, err))
    return problems


def main():
    binary = os.environ.get("NH_BINARY")
    source = os.environ.get("NH_SOURCE_DIR")
    if not binary or not source:
        print("bad_input: set NH_BINARY and NH_SOURCE_DIR", file=sys.stderr)
        return 1
    bad_dir = os.path.join(source, "tests", "bad")
    failed = 0
    for fixture, overrides, where, key in CASES:
        problems = check_case(binary, bad_dir, fixture, overrides, where, key)
        if problems:
            failed += 1
            print("FAILED %s %s" % (fixture, overrides), file=sys.stderr)
            for p in problems:
                print("  " + p, file=sys.stderr)
    for fixture, overrides, env, where, key in ENV_CASES:
        problems = check_case(binary, bad_dir, fixture, overrides, where, key, env=env)
        status, _, err, args = run(binary, os.path.join(bad_dir, fixture), [], env=env)
        if status != 0 or err.strip():
            problems.append("%s without the overrides: expected status 0 and no stderr, got "
                            "%s, %r" % (" ".join(args), status, err))
        if problems:
            failed += 1
            print("FAILED %s %s %s" % (fixture, overrides, env), file=sys.stderr)
            for p in problems:
                print("  " + p, file=sys.stderr)
    for fixture, overrides, where, key in SIZE_CASES:
        # CPU seconds of the child: what `check` spent, whatever the load of
        # a shared machine does to the wall clock (kept below 10 s too).
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.monotonic()
        problems = check_case(binary, bad_dir, fixture, overrides, where, key)
        elapsed = time.monotonic() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        _, _, err, _ = run(binary, os.path.join(bad_dir, fixture), overrides)
        if cpu > 1.0 or elapsed > 10.0:
            problems.append("answered after %.2f s of CPU (%.2f s wall), expected within 1 s"
                            % (cpu, elapsed))
        if " of memory" not in err:
            problems.append("message: expected the estimated memory: %r" % err)
        if problems:
            failed += 1
            print("FAILED %s %s" % (fixture, overrides), file=sys.stderr)
            for p in problems:
                print("  " + p, file=sys.stderr)
    with tempfile.TemporaryDirectory() as out:
        for fixture, overrides, where, key in PLAN_CASES:
            command = ("plan", "--out", os.path.join(out, "plan"), "--quiet")
            problems = check_case(binary, bad_dir, fixture, overrides, where, key, command)
            if os.path.exists(os.path.join(out, "plan")):
                problems.append("plan: wrote its folder before refusing the scene")
            if problems:
                failed += 1
                print("FAILED plan %s %s" % (fixture, overrides), file=sys.stderr)
                for p in problems:
                    print("  " + p, file=sys.stderr)
    for fixture, overrides in VALID:
        status, _, err, args = run(binary, os.path.join(bad_dir, fixture), overrides)
        if status != 0 or err.strip():
            failed += 1
            print("FAILED valid scene: %s\n  expected status 0 and no stderr, got %s, %r"
                  % (" ".join(args), status, err), file=sys.stderr)
    scene = os.path.join(bad_dir, "set_base.yaml")
    for argv, want in COMMAND_LINES:
        args = [binary] + [scene if a == "SCENE" else a for a in argv]
        with tempfile.TemporaryDirectory() as cwd:
            rc, _, stderr = measured(args, cwd=cwd)
            left = os.listdir(cwd)
        lines = stderr.split("\n")
        problems = []
        if rc != 2:
            problems.append("exit status: expected 2, got %s" % rc)
        if not (len(lines) == 2 and lines[1] == ""):
            problems.append("stderr: expected exactly one line")
        if want not in stderr or "usage: needlehex %s SCENE.yaml" % argv[0] not in stderr:
            problems.append("message: expected %r and the usage line" % want)
        if left:
            problems.append("the folder it ran in is not empty: %s" % left)
        if problems:
            failed += 1
            print("FAILED %s\n  stderr: %r\n  %s" % (" ".join(args), stderr,
                                                     "\n  ".join(problems)), file=sys.stderr)
    # Every fixture in tests/bad/ must be exercised by a case above.
    used = {c[0] for c in CASES} | {v[0] for v in VALID}
    for name in sorted(os.listdir(bad_dir)):
        if name.endswith(".yaml") and name not in used:
            failed += 1
            print("FAILED: tests/bad/%s has no case in bad_input.py" % name, file=sys.stderr)
    # The campaign's limits, for every child run above.
    for seconds, mb, shown in RECORD:
        if (seconds > MAX_SECONDS or mb > MAX_MB) and not os.environ.get("NH_SANITIZED"):
            failed += 1
            print("FAILED %s: %.2f s, %.0f MB (at most %g s and %g MB)"
                  % (shown, seconds, mb, MAX_SECONDS, MAX_MB), file=sys.stderr)
    slowest, largest = max(RECORD), max(RECORD, key=lambda r: r[1])
    print("bad_input: %d commands (%d bad scenes, %d with an environment, %d size, %d plan, "
          "%d valid, %d command lines); "
          "slowest %.2f s (%s), largest %.0f MB (%s)"
          % (len(RECORD), len(CASES), len(ENV_CASES), len(SIZE_CASES), len(PLAN_CASES), len(VALID),
             len(COMMAND_LINES), slowest[0], slowest[2].split(" ", 1)[1], largest[1],
             largest[2].split(" ", 1)[1]))
    if failed:
        print("bad_input: %d failure(s)" % failed, file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
