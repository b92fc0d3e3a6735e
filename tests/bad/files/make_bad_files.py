#!/usr/bin/python3
"""make_bad_files — malformed and unusual files for every reader of a file a
scene names (issue 31): NIfTI label images, STL surfaces, refinement
templates and checkpoints, each with a small scene that names it.

    make_bad_files.py OUTDIR [--binary NEEDLEHEX] [--corpus DIR]    (prints the counts)

(--binary: the checkpoints need a run to start from; --corpus: the files as
fuzz seeds, DIR/READER/NNN-NAME, for tools/fuzz.sh and the replay tests.)

Each case is one folder OUTDIR/NNN-NAME/ holding the file and `scene.yaml`.
A case is either bad (the runner, tests/bad_files.py, requires exit 2 and
one stderr line naming the file, the scene key where the scene reader
already prefixes it, and the problem: every string of `expect`) or a
control (`ok`: a valid but unusual file that must pass: byte-swapped,
NIfTI-2, a hollow surface, ...). The files are written here from the
formats' specifications (NIfTI-1/2 header layouts, STL, templates/README.md,
the checkpoint layout of src/sim/checkpoint.c), not with the project's
code; the valid NIfTI controls are read back with nibabel as an
independent check of the writer.

Extending: add a `case(...)` call in one of the make_* functions below; the
writer gets the case's folder and returns the name of the file the scene
names. Streams (FIFO) are fed by the runner from `feed` (bytes, repeated up
to `feed_bytes`).
"""
import gzip
import math
import os
import shutil
import struct
import subprocess
import sys

import numpy as np

NAN, INF = float("nan"), float("inf")


class Case:
    def __init__(self, name, reader, key, write, expect=(), ok=False, unit=0.001, feed=None,
                 feed_bytes=0):
        self.name, self.reader, self.key, self.write = name, reader, key, write
        self.expect, self.ok, self.unit = list(expect), ok, unit
        self.feed, self.feed_bytes = feed, feed_bytes
        self.dir = self.file = None


CASES = []


def case(*args, **kw):
    CASES.append(Case(*args, **kw))


# ---------------------------------------------------------------- scenes ----
# The key each kind of case names its file at, and its line in the scene
# below (counted by hand), as the message reports them: "scene.yaml:LINE:
# KEY:" (a template is loaded when the run is built, and reported at the
# scene's adapt.template all the same); a checkpoint comes from --restart.
KEY = {"mask": "tissue.domain.mask.file", "labels": "tissue.labels.file",
       "surface": "tissue.domain.surface.file", "template": "adapt.template",
       "restart": "--restart"}
LINE = {"mask": 5, "labels": 7, "surface": 5, "template": 9}

# A static scene over a 16 mm box (the images' extent) whose tissue section
# names the file; {file} and {unit} are filled in per case.
SCENE_HEAD = "name: bad\ntime: {{mode: static, step: 1, end: 1}}\ntissue:\n"
SCENE_TAIL = "  material: {{young: 1000, poisson: 0.3}}\n"
BOX = "    box: {{min: [0, 0, 0], max: [0.016, 0.016, 0.016]}}\n"
SCENES = {
    "mask": SCENE_HEAD + "  domain:\n    mask: {{file: {file}, labels: [1]}}\n"
                         "  grid: [2, 2, 2]\n" + SCENE_TAIL,
    "labels": SCENE_HEAD + "  domain:\n" + BOX + "  grid: [2, 2, 2]\n"
                           "  labels: {{file: {file}}}\n" + SCENE_TAIL,
    "surface": SCENE_HEAD + "  domain:\n    surface: {{file: {file}, unit: {unit!r}}}\n"
                            "  grid: [2, 2, 2]\n" + SCENE_TAIL,
    "template": SCENE_HEAD + "  domain:\n" + BOX + "  grid: [2, 2, 2]\n" + SCENE_TAIL +
                "adapt:\n  template: {file}\n",
    # A refined mesh (adapt, max_level 1) so the checkpoint holds a tree.
    "restart": """name: ck
time: {mode: dynamic, step: 0.01, steps: 4}
tissue:
  domain:
    box: {min: [0, 0, 0], max: [0.02, 0.01, 0.01]}
  grid: [2, 1, 1]
  material: {young: 1.0e6, poisson: 0.3, density: 1000}
  fixed:
    - {box: {min: [-1, -1, -1], max: [0.0001, 1, 1]}}
  loads:
    - {box: {min: [0.015, -1, -1], max: [1, 1, 1]}, force: [0, 1.0, 0]}
adapt:
  marking: {strategy: max, theta: 0.5}
  max_level: 1
output:
  checkpoint: 2
""",
}


def command(c, binary):
    """The command line that reads the case's file."""
    scene = os.path.join(c.dir, "scene.yaml")
    if c.key == "restart":
        return [binary, "run", scene, "--restart", c.dir, "--quiet"]
    return [binary, "check", scene]


# ----------------------------------------------------------------- NIfTI ----
# Header layouts (NIfTI-1: nifti1.h, 348 bytes; NIfTI-2: nifti2.h, 540 bytes):
# (field, byte offset, struct format).
N1 = [("sizeof_hdr", 0, "i"), ("dim", 40, "8h"), ("intent_code", 68, "h"),
      ("datatype", 70, "h"), ("bitpix", 72, "h"), ("pixdim", 76, "8f"),
      ("vox_offset", 108, "f"), ("scl_slope", 112, "f"), ("scl_inter", 116, "f"),
      ("xyzt_units", 123, "B"), ("qform_code", 252, "h"), ("sform_code", 254, "h"),
      ("quatern_b", 256, "f"), ("quatern_c", 260, "f"), ("quatern_d", 264, "f"),
      ("qoffset_x", 268, "f"), ("qoffset_y", 272, "f"), ("qoffset_z", 276, "f"),
      ("srow_x", 280, "4f"), ("srow_y", 296, "4f"), ("srow_z", 312, "4f"), ("magic", 344, "4s")]
N2 = [("sizeof_hdr", 0, "i"), ("magic", 4, "8s"), ("datatype", 12, "h"), ("bitpix", 14, "h"),
      ("dim", 16, "8q"), ("pixdim", 104, "8d"), ("vox_offset", 168, "q"),
      ("scl_slope", 176, "d"), ("scl_inter", 184, "d"), ("qform_code", 344, "i"),
      ("sform_code", 348, "i"), ("quatern_b", 352, "d"), ("quatern_c", 360, "d"),
      ("quatern_d", 368, "d"), ("qoffset_x", 376, "d"), ("qoffset_y", 384, "d"),
      ("qoffset_z", 392, "d"), ("srow_x", 400, "4d"), ("srow_y", 432, "4d"),
      ("srow_z", 464, "4d"), ("xyzt_units", 500, "i"), ("intent_code", 504, "i")]
DTYPES = {2: "u1", 4: "i2", 8: "i4", 16: "f4", 64: "f8", 256: "i1", 512: "u2", 768: "u4",
          1024: "i8", 1280: "u8"}
SHAPE = (8, 8, 8)  # 2 mm voxels; label 1 in the cube [2, 6)^3


def labels(dtype="u1"):
    a = np.zeros(SHAPE, dtype)
    a[2:6, 2:6, 2:6] = 1
    return a


def nifti_fields(version, **over):
    """A valid header (8^3 uint8 voxels of 2 mm, qform and sform both the
    diagonal, units mm), with `over` replacing fields."""
    f = dict(sizeof_hdr=348 if version == 1 else 540, dim=[3, *SHAPE, 1, 1, 1, 1],
             intent_code=0, datatype=2, bitpix=8, pixdim=[1, 2, 2, 2, 1, 1, 1, 1],
             vox_offset=352 if version == 1 else 544, scl_slope=NAN, scl_inter=NAN,
             xyzt_units=2, qform_code=1, sform_code=1, quatern_b=0, quatern_c=0, quatern_d=0,
             qoffset_x=0, qoffset_y=0, qoffset_z=0, srow_x=[2, 0, 0, 0], srow_y=[0, 2, 0, 0],
             srow_z=[0, 0, 2, 0], magic=b"n+1\0" if version == 1 else b"n+2\0\r\n\x1a\n")
    f.update(over)
    return f


def nifti_header(version=1, endian="<", **over):
    f = nifti_fields(version, **over)
    out = bytearray(348 if version == 1 else 540)
    for name, off, fmt in (N1 if version == 1 else N2):
        v = f[name]
        struct.pack_into(endian + fmt, out, off, *(v if isinstance(v, list) else [v]))
    return bytes(out)


def nifti(version=1, endian="<", data=None, dtype=None, extra=b"", cut=None, **over):
    """Header, 4 extension bytes, voxels; `cut` bytes dropped from the end."""
    if data is None:
        data = labels(DTYPES[over.get("datatype", 2)] if dtype is None else dtype)
    head = nifti_header(version, endian, **over)
    raw = head + b"\0\0\0\0" + data.astype(data.dtype.newbyteorder(endian)).tobytes(order="F")
    raw += extra
    return raw[:len(raw) - cut] if cut else raw


def put(name, data, gz=False):
    def write(d):
        path = os.path.join(d, name)
        with open(path, "wb") as f:
            f.write(gzip.compress(data, mtime=0) if gz else data)
        return name
    return write


def nifti_case(name, expect, ok=False, gz=False, version=1, keys=("mask",), **kw):
    ext = ".nii.gz" if gz else ".nii"
    for key in keys:
        case(f"nifti/{key}/{name}", "nifti", key, put("image" + ext, nifti(version, **kw), gz),
             expect, ok)


def make_nifti():
    # Controls: what real files look like, read as they must be.
    for v in (1, 2):
        for gz in (False, True):
            nifti_case(f"ok_v{v}{'_gz' if gz else ''}", [], ok=True, gz=gz, version=v,
                       keys=("mask", "labels"))
        nifti_case(f"ok_v{v}_bigendian", [], ok=True, version=v, endian=">", datatype=4, bitpix=16)
        nifti_case(f"ok_v{v}_qform_only", [], ok=True, version=v, sform_code=0)
        nifti_case(f"ok_v{v}_pixdim_only", [], ok=True, version=v, sform_code=0, qform_code=0)
        nifti_case(f"ok_v{v}_float_whole", [], ok=True, version=v, datatype=16, bitpix=32)
        nifti_case(f"ok_v{v}_slope", [], ok=True, version=v, datatype=4, bitpix=16,
                   data=labels("i2") * 2, scl_slope=0.5, scl_inter=0.0)
        nifti_case(f"ok_v{v}_qform_180", [], ok=True, version=v, sform_code=0, quatern_b=1.0)
    nifti_case("ok_2d_dim0_2", [], ok=True, dim=[2, 8, 8, 1, 1, 1, 1, 1], data=labels()[:, :, 3:4])
    # Header fields, each refused by name, in NIfTI-1 and NIfTI-2 (and gzip'd).
    bad_fields = []
    for d in (1, 2, 3):
        for v in (0, -1, -32768):
            dim = [3, *SHAPE, 1, 1, 1, 1]
            dim[d] = v
            bad_fields.append((f"dim{d}_{v}", [f"dim[{d}] = {v}"], dict(dim=dim)))
    for v in (0, -1, 8, 100):
        bad_fields.append((f"dim0_{v}", [f"dim[0] = {v}"], dict(dim=[v, *SHAPE, 1, 1, 1, 1])))
    bad_fields.append(("dim4_time", ["not a 3D image"], dict(dim=[4, *SHAPE, 2, 1, 1, 1])))
    bad_fields.append(("dim5_vector", ["not a 3D image"], dict(dim=[5, *SHAPE, 1, 3, 1, 1])))
    for d in (1, 2, 3):
        for v in (NAN, INF, -INF, 0.0, -2.0):
            p = [1, 2, 2, 2, 1, 1, 1, 1]
            p[d] = v
            bad_fields.append((f"pixdim{d}_{v}", [f"pixdim[{d}] = {v:g}".replace("inf", "inf")],
                               dict(pixdim=p)))
    bad_fields.append(("qfac_nan", ["pixdim[0]"], dict(pixdim=[NAN, 2, 2, 2, 1, 1, 1, 1])))
    for q in ("quatern_b", "quatern_c", "quatern_d"):
        for v in (NAN, INF, -INF):
            bad_fields.append((f"{q}_{v}", ["quaternion", "not finite"], {q: v}))
    bad_fields.append(("quatern_norm_1.27", ["norm", "not a rotation"],
                       dict(quatern_b=0.9, quatern_c=0.9)))
    bad_fields.append(("quatern_norm_2", ["norm", "not a rotation"], dict(quatern_d=-2.0)))
    for q in ("qoffset_x", "qoffset_y", "qoffset_z"):
        for v in (NAN, INF):
            bad_fields.append((f"{q}_{v}", ["qoffset", "not finite"], {q: v}))
    for r in ("srow_x", "srow_y", "srow_z"):
        for c in (0, 3):
            for v in (NAN, INF):
                row = {"srow_x": [2, 0, 0, 0], "srow_y": [0, 2, 0, 0], "srow_z": [0, 0, 2, 0]}[r]
                row = list(row)
                row[c] = v
                bad_fields.append((f"{r}{c}_{v}", ["sform", "not finite"], {r: row}))
    bad_fields.append(("sform_zero", ["sform", "singular"],
                       dict(srow_x=[0] * 4, srow_y=[0] * 4, srow_z=[0] * 4)))
    bad_fields.append(("sform_rank2", ["sform", "singular"],
                       dict(srow_x=[2, 0, 0, 0], srow_y=[2, 0, 0, 0], srow_z=[0, 0, 2, 0])))
    for code in (-1, 6, 1000):
        bad_fields.append((f"qform_code_{code}", [f"qform_code = {code}"], dict(qform_code=code)))
        bad_fields.append((f"sform_code_{code}", [f"sform_code = {code}"], dict(sform_code=code)))
    for u in (4, 5, 7):
        bad_fields.append((f"xyzt_units_{u}", [f"xyzt_units = {u}"], dict(xyzt_units=u)))
    for dt, what in ((32, "COMPLEX64"), (128, "RGB24"), (1536, "FLOAT128"), (2304, "RGBA32"),
                     (0, "UNKNOWN"), (9999, "9999")):
        bad_fields.append((f"datatype_{dt}", ["not a label type"],
                           dict(datatype=dt, data=labels())))
    bad_fields.append(("scl_inter_inf", ["scl_inter = inf"], dict(scl_slope=1.0, scl_inter=INF)))
    for name, expect, over in bad_fields:
        nifti_case(name, expect, **over)
        nifti_case(name + "_v2", expect, version=2, **over)
    for name, expect, over in bad_fields[::4]:  # a sample gzip'd: the same header checks
        nifti_case(name + "_gz", expect, gz=True, **over)
    for name, expect, over in bad_fields[::7]:  # and through tissue.labels
        nifti_case(name, expect, keys=("labels",), **over)
    # vox_offset (NIfTI-1 keeps it in a float).
    for v, expect in ((NAN, "vox_offset = nan"), (100.5, "vox_offset = 100.5"),
                      (0.0, "vox_offset = 0"), (-352.0, "vox_offset = -352"),
                      (300.0, "vox_offset = 300")):
        nifti_case(f"vox_offset_{v}", [expect], vox_offset=v)
    nifti_case("vox_offset_beyond", ["truncated"], vox_offset=100352.0)
    nifti_case("vox_offset_1e30", ["limits.max_file_bytes"], vox_offset=1e30)
    nifti_case("vox_offset_beyond_v2", ["truncated"], version=2, vox_offset=100544)
    nifti_case("vox_offset_beyond_gz", ["vox_offset"], gz=True, vox_offset=100352.0)
    # Magic, version, byte order.
    nifti_case("magic_bad", ["not a NIfTI file"], magic=b"abc\0")
    nifti_case("magic_analyze", ["not a NIfTI file", "Analyze"], magic=b"\0\0\0\0")
    nifti_case("magic_two_file_in_nii", ["rename"], magic=b"ni1\0")
    nifti_case("sizeof_hdr_349", ["not a NIfTI file"], sizeof_hdr=349)
    case("nifti/mask/header_v2_cut_400", "nifti", "mask", put("image.nii", nifti_header(2)[:400]),
         ["NIfTI-2 header is truncated"])
    case("nifti/mask/header_v1_cut_300", "nifti", "mask", put("image.nii", nifti_header(1)[:300]),
         ["not a NIfTI file", "348"])
    # Sizes: voxels and bytes beyond the limits, refused from the header (a
    # gzip'd header with a few bytes of data, as a hostile file would be).
    for dims in ((999, 999, 999), (32767, 32767, 32767), (20000, 20000, 1)):
        hdr = nifti_header(1, dim=[3, *dims, 1, 1, 1, 1]) + b"\0" * 20
        case(f"nifti/mask/huge_{'x'.join(map(str, dims))}_gz", "nifti", "mask",
             put("image.nii.gz", hdr, True), ["limits.max_voxels"])
    hdr = nifti_header(2, dim=[3, 10 ** 6, 10 ** 6, 10 ** 6, 1, 1, 1, 1]) + b"\0" * 20
    case("nifti/mask/huge_1e18_v2_gz", "nifti", "mask", put("image.nii.gz", hdr, True),
         ["limits.max_voxels"])
    # NIfTI-2's 64-bit dims: 65535^3 and int64's largest cubed (whose product
    # overflows any integer: the reader multiplies in doubles).
    for name, n in (("65535", 65535), ("int64max", 2 ** 63 - 1)):
        hdr = nifti_header(2, dim=[3, n, n, n, 1, 1, 1, 1]) + b"\0" * 20
        case(f"nifti/mask/huge_{name}_cubed_v2_gz", "nifti", "mask", put("image.nii.gz", hdr, True),
             ["limits.max_voxels"])
    # Voxel sizes and offsets at double's ends (NIfTI-2 keeps them in
    # doubles): 1e-300, 1e300 and 1e305 mm make the transform singular or
    # infinite once in metres; 1e7 mm voxels are fine but 8 of them reach 80 km;
    # an offset of 1e20 mm swallows the 16 mm extent (the box had max = min:
    # "domain box: max[0] must exceed min[0]" without file or key, before
    # NH_IMAGE_MAX_COORDINATE); 2 km is farther than any patient.
    for v, expect in ((1e-300, "singular or not finite"), (1e300, "singular or not finite"),
                      (1e305, "singular or not finite"), (1e7, "from the origin")):
        nifti_case(f"pixdim_{v:g}_v2", [expect], version=2, sform_code=0, qform_code=0,
                   pixdim=[1, v, 2, 2, 1, 1, 1, 1])
        nifti_case(f"pixdim_{v:g}_qform_v2", [expect], version=2, sform_code=0,
                   pixdim=[1, v, v, v, 1, 1, 1, 1])
    for v in (1e20, 2e6):
        nifti_case(f"qoffset_{v:g}_v2", ["from the origin", "qform"], version=2, sform_code=0,
                   qoffset_x=v)
        nifti_case(f"srow_offset_{v:g}_v2", ["from the origin", "sform"], version=2,
                   srow_z=[0, 0, 2, -v])
    nifti_case("ok_v2_qoffset_500m", [], ok=True, version=2, sform_code=0, qoffset_x=5e5)
    # Scaling at double's ends: every label becomes 1e300 or 1e-300, not a
    # whole number the reader could hold, named by its voxel.
    for s in (1e300, 1e-300):
        nifti_case(f"slope_{s:g}_v2", ["voxel [2, 2, 2]", f"holds {s:g}"], version=2, datatype=4,
                   bitpix=16, scl_slope=s, scl_inter=0.0)
        nifti_case(f"inter_{s:g}_v2", ["voxel [0, 0, 0]", f"holds {s:g}"], version=2,
                   datatype=4, bitpix=16, scl_slope=1.0, scl_inter=s)
    hdr = nifti_header(1, dim=[3, 600, 600, 500, 1, 1, 1, 1], datatype=64, bitpix=64) + b"\0" * 8
    case("nifti/mask/bytes_1.4e9_float64_gz", "nifti", "mask", put("image.nii.gz", hdr, True),
         ["truncated"])  # under both limits: refused as it is read, not allocated first
    hdr = nifti_header(1, dim=[3, 1200, 1200, 100, 1, 1, 1, 1], datatype=1280, bitpix=64)
    case("nifti/mask/bytes_1.2e9_uint64", "nifti", "mask", put("image.nii", hdr + b"\0" * 16),
         ["truncated"])
    hdr = nifti_header(1, vox_offset=4.5e9)
    case("nifti/mask/bytes_4.5e9_offset_gz", "nifti", "mask", put("image.nii.gz", hdr, True),
         ["limits.max_file_bytes"])
    # Data: shorter or longer than the header says, plain and gzip'd.
    for cut in (1, 256, 512):
        nifti_case(f"truncated_{cut}", ["truncated"], cut=cut)
        nifti_case(f"truncated_{cut}_gz", ["truncated"], gz=True, cut=cut)
        nifti_case(f"truncated_{cut}_v2", ["truncated"], version=2, cut=cut)
    nifti_case("header_only", ["truncated"], cut=516)
    nifti_case("header_only_gz", ["before vox_offset = 352"], gz=True, cut=516)
    nifti_case("extension_only_gz", ["the file ends (truncated) after 0 of the 512"], gz=True,
               cut=512)
    for n in (1, 1000):
        nifti_case(f"extra_{n}", ["longer than its header says"], extra=b"\1" * n)
        nifti_case(f"extra_{n}_gz", ["goes on after"], gz=True, extra=b"\1" * n)
        nifti_case(f"extra_{n}_v2_gz", ["goes on after"], gz=True, version=2, extra=b"\1" * n)
    # Labels that are not whole numbers, named by their voxel [3, 4, 5].
    for dt, v in ((16, NAN), (16, 2.5), (16, INF), (16, -INF), (64, NAN), (64, 0.1),
                  (64, 1e10), (64, -3e9), (16, 3e9)):
        a = labels(DTYPES[dt])
        a[3, 4, 5] = v
        for gz in (False, True):
            nifti_case(f"label_{DTYPES[dt]}_{v}{'_gz' if gz else ''}",
                       ["voxel [3, 4, 5]", f"holds {v:g}"], gz=gz, datatype=dt,
                       bitpix=8 * a.itemsize, data=a)
        nifti_case(f"label_{DTYPES[dt]}_{v}", ["voxel [3, 4, 5]"], keys=("labels",), datatype=dt,
                   bitpix=8 * a.itemsize, data=a)
    for dt, v in ((1024, 2 ** 40), (1280, 2 ** 63), (768, 2 ** 31)):
        a = labels(DTYPES[dt])
        a[3, 4, 5] = v
        nifti_case(f"label_{DTYPES[dt]}_{v}", ["voxel [3, 4, 5]"], datatype=dt,
                   bitpix=8 * a.itemsize, data=a)
    nifti_case("label_slope_half", ["voxel [2, 2, 2]", "holds 0.5"], scl_slope=0.5, scl_inter=0.0)
    # Files that are not NIfTI at all, or broken gzip streams.
    good = nifti(1)
    for name, data, gz, expect in (
            ("empty", b"", False, "not a NIfTI file"), ("empty_gz", b"", True, "not a NIfTI"),
            ("text", b"this is not an image\n" * 3, False, "not a NIfTI file"),
            ("zeros_348", b"\0" * 348, False, "not a NIfTI file"),
            ("random", np.random.default_rng(1).bytes(4096), False, "not a NIfTI file")):
        case(f"nifti/mask/{name}", "nifti", "mask",
             put("image.nii.gz" if gz else "image.nii", data, gz), [expect])
    z = gzip.compress(good, mtime=0)
    for name, data, expect in (
            ("gz_cut_half", z[:len(z) // 2], "image.nii.gz"),
            ("gz_cut_header", z[:30], "not a NIfTI file"),
            ("gz_flipped", z[:40] + bytes([z[40] ^ 0xFF]) + z[41:], "damaged gzip stream"),
            ("gz_crc", z[:-8] + bytes([z[-8] ^ 1]) + z[-7:], "damaged gzip stream")):
        case(f"nifti/mask/{name}", "nifti", "mask", put("image.nii.gz", data), [expect])
    # zlib reads a plain file named .gz through, and ignores bytes after the
    # gzip stream (as `gzip -d` does, with a warning): the voxels are whole.
    case("nifti/mask/ok_plain_named_gz", "nifti", "mask", put("image.nii.gz", good), [], ok=True)
    case("nifti/mask/ok_gz_bytes_after", "nifti", "mask", put("image.nii.gz", z + b"garbage"), [],
         ok=True)
    # Names and kinds of file.
    case("nifti/mask/dev_zero", "nifti", "mask", symlink("image.nii", "/dev/zero"),
         ["not a regular file"])
    case("nifti/mask/fifo", "nifti", "mask", fifo("image.nii"), ["not a regular file"],
         feed=b"\0", feed_bytes=1 << 20)
    case("nifti/mask/folder", "nifti", "mask", folder("image.nii"), ["cannot read"])
    case("nifti/mask/no_extension", "nifti", "mask", put("image.dat", good),
         ["not a NIfTI file name"])
    # .hdr/.img pairs.
    pair = nifti(1, magic=b"ni1\0", vox_offset=0.0)
    hdr, img = pair[:348], pair[352:]
    case("nifti/mask/ok_pair", "nifti", "mask", pair_writer(hdr, img), [], ok=True)
    case("nifti/mask/pair_no_img", "nifti", "mask", pair_writer(hdr, None), ["voxel (.img)"])
    case("nifti/mask/pair_img_short", "nifti", "mask", pair_writer(hdr, img[:-1]),
         ["its voxel file", "image.img", "truncated"])
    case("nifti/mask/pair_img_long", "nifti", "mask", pair_writer(hdr, img + b"\0"),
         ["its voxel file", "longer than its header says"])
    a = labels()
    a[1, 2, 3] = 7
    f = nifti(1, magic=b"ni1\0", vox_offset=0.0, datatype=16, bitpix=32,
              data=labels("f4") + np.where(a == 7, 0.25, 0).astype("f4"))
    case("nifti/mask/pair_img_fraction", "nifti", "mask", pair_writer(f[:348], f[352:]),
         ["its voxel file", "voxel [1, 2, 3]", "holds 0.25"])
    case("nifti/mask/pair_onefile_magic", "nifti", "mask", pair_writer(hdr[:344] + b"n+1\0", img),
         ["rename"])


def symlink(name, target):
    def write(d):
        os.symlink(target, os.path.join(d, name))
        return name
    return write


def fifo(name):
    def write(d):
        os.mkfifo(os.path.join(d, name))
        return name
    return write


def folder(name):
    def write(d):
        os.mkdir(os.path.join(d, name))
        return name
    return write


def sparse(name, size, head=b""):
    def write(d):
        with open(os.path.join(d, name), "wb") as f:
            f.write(head)
            f.truncate(size)
        return name
    return write


def pair_writer(hdr, img):
    def write(d):
        with open(os.path.join(d, "image.hdr"), "wb") as f:
            f.write(hdr)
        if img is not None:
            with open(os.path.join(d, "image.img"), "wb") as f:
                f.write(img)
        return "image.hdr"
    return write


# ------------------------------------------------------------------- STL ----
def sphere(r=20.0, c=(0.0, 0.0, 0.0), n=12, wind=1):
    """A UV sphere of radius r (file units) as triangles, outward (right-handed).
    wind=2: azimuth doubled and radius r (1 + 0.2 sin(p + 0.1)), a shell that
    goes twice around the axis through itself."""
    V = [(0.0, 0.0, r)]
    for i in range(1, n):
        t = math.pi * i / n
        for j in range(2 * n):
            p = math.pi * j / n
            q = r if wind == 1 else r * (1 + 0.2 * math.sin(p + 0.1))
            V.append((q * math.sin(t) * math.cos(wind * p), q * math.sin(t) * math.sin(wind * p),
                      q * math.cos(t)))
    V.append((0.0, 0.0, -r))
    V = [tuple(v[k] + c[k] for k in range(3)) for v in V]
    ring = lambda i, j: 1 + (i - 1) * 2 * n + j % (2 * n)
    T = [(0, ring(1, j), ring(1, j + 1)) for j in range(2 * n)]
    for i in range(1, n - 1):
        for j in range(2 * n):
            a, b, cc, d = ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)
            T += [(a, b, d), (b, cc, d)]
    T += [(ring(n - 1, j), len(V) - 1, ring(n - 1, j + 1)) for j in range(2 * n)]
    return [[V[k] for k in t] for t in T]


def cube(h=10.0, lo=(0.0, 0.0, 0.0)):
    P = [(lo[0] + h * (i & 1), lo[1] + h * (i >> 1 & 1), lo[2] + h * (i >> 2 & 1)) for i in range(8)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    T = []
    for a, b, c, d in quads:
        T += [[P[a], P[b], P[c]], [P[a], P[c], P[d]]]
    return T


def cylinder_fans(n, r=10.0, length=40.0):
    """A closed cylinder along x (radius r, file units) of n side segments,
    each cap a fan of n triangles from its centre, outward."""
    rim = [(r * math.cos(2 * math.pi * j / n), r * math.sin(2 * math.pi * j / n)) for j in range(n)]
    T = []
    for j in range(n):
        (y0, z0), (y1, z1) = rim[j], rim[(j + 1) % n]
        a, b, c, d = (0.0, y0, z0), (0.0, y1, z1), (length, y1, z1), (length, y0, z0)
        T += [[a, b, c], [a, c, d]]
        T.append([(0.0, 0.0, 0.0), b, a])
        T.append([(length, 0.0, 0.0), d, c])
    return T


def flip(tris):
    return [[t[0], t[2], t[1]] for t in tris]


def ascii_stl(tris, name="s", fmt="%.17g"):
    out = [f"solid {name}\n"]
    for t in tris:
        out.append("facet normal 0 0 0\n outer loop\n")
        for v in t:
            out.append(" vertex " + " ".join(fmt % x if isinstance(x, float) else str(x)
                                             for x in v) + "\n")
        out.append(" endloop\nendfacet\n")
    out.append(f"endsolid {name}\n")
    return "".join(out).encode()


def binary_stl(tris, count=None, head=b"binary stl"):
    out = bytearray(head.ljust(80, b"\0")[:80])
    out += struct.pack("<I", len(tris) if count is None else count)
    for t in tris:
        out += struct.pack("<3f", 0, 0, 0)
        for v in t:
            out += struct.pack("<3f", *v)
        out += b"\0\0"
    return bytes(out)


def stl_case(name, data, expect, ok=False, unit=0.001, file="surface.stl"):
    case(f"stl/{name}", "stl", "surface", put(file, data), expect, ok, unit=unit)


def make_stl():
    S = sphere()
    stl_case("ok_ascii_sphere", ascii_stl(S), [], ok=True)
    stl_case("ok_binary_sphere", binary_stl(S), [], ok=True)
    stl_case("ok_binary_solid_header", binary_stl(S, head=b"solid but binary"), [], ok=True)
    stl_case("ok_inverted_whole", ascii_stl(flip(S)), [], ok=True)  # orientation-free
    stl_case("ok_hollow", ascii_stl(S + flip(sphere(8.0))), [], ok=True)  # a cavity faces inwards
    stl_case("ok_two_shells_apart", ascii_stl(S + sphere(10.0, (50.0, 0, 0))), [], ok=True)
    stl_case("ok_crlf_tabs", ascii_stl(S).replace(b"\n", b"\r\n").replace(b" ", b"\t"), [],
             ok=True)
    stl_case("ok_unit_m", ascii_stl(sphere(0.02)), [], ok=True, unit=1.0)
    stl_case("ok_cube", ascii_stl(cube()), [], ok=True)
    # Geometry that is not what it says.
    stl_case("overlapping_shells", ascii_stl(S + sphere(20.0, (15.0, 0, 0))),
             ["by the inside test", "by the divergence theorem", "overlapping shells"])
    stl_case("overlapping_shells_binary", binary_stl(S + sphere(20.0, (15.0, 0, 0))),
             ["overlapping shells"])
    stl_case("nested_same_orientation", ascii_stl(S + sphere(8.0)), ["overlapping shells"])
    stl_case("duplicate_shell", ascii_stl(S + S), ["overlapping shells"])  # every edge shared by 4
    stl_case("shell_inverted", ascii_stl(S + flip(sphere(10.0, (50.0, 0, 0)))),
             ["facing the wrong way"])
    stl_case("cube_inside_inverted", ascii_stl(cube(20.0) + flip(cube(10.0, (30.0, 0, 0)))),
             ["inconsistent orientation"])
    # One shell wound twice around the z axis (azimuth 2p, radius varying
    # with p): it crosses itself, and its core has winding number 2.
    stl_case("self_intersecting_twice_wound", ascii_stl(sphere(wind=2)), ["differ by", "intersect"])
    # (The upper hemisphere folded down under the lower one, z -> -2 z, is no
    # such case: it bounds the solid between two nested bowls, once.)
    folded = [[(v[0], v[1], -2 * v[2] if v[2] > 0 else v[2]) for v in t] for t in S]
    stl_case("ok_folded_bowls", ascii_stl(folded), [], ok=True)
    sheet = [[(0, 0, 0), (10, 0, 0), (10, 10, 0)], [(0, 0, 0), (10, 10, 0), (0, 10, 0)]]
    stl_case("flat_doubled_sheet", ascii_stl(sheet + flip(sheet)), ["encloses no volume"])
    flat = [[(v[0], v[1], 0.0) for v in t] for t in cube()]
    stl_case("flat_cube", ascii_stl(flat), ["encloses no volume"])
    tilted = [[(0, 0, 0), (10, 0, 5), (10, 10, 5)], [(0, 0, 0), (10, 10, 5), (0, 10, 0)]]
    stl_case("flat_tilted_sheet", binary_stl(tilted + flip(tilted)), ["encloses no volume"])
    stl_case("open_hole", ascii_stl(S[1:]), ["not a closed surface"])
    stl_case("nonmanifold_edge", ascii_stl(cube() + [[(0, 0, 0), (10, 0, 0), (5, -5, -5)]]),
             ["not a closed surface"])
    stl_case("three_triangles", ascii_stl(cube()[:3]), ["not a closed surface"])
    stl_case("zero_area_only", ascii_stl([[(0, 0, 0), (1, 1, 1), (2, 2, 2)]] * 6),
             ["0 triangles of non-zero area"])
    for unit, expect in ((1.0, "larger than 10 m"), (1000.0, "larger than 10 m"),
                         (1e6, "larger than 10 m"), (1e300, "larger than 10 m"),
                         (1e307, "not a finite length")):
        stl_case(f"unit_{unit:g}", ascii_stl(S), [expect], unit=unit)
    # A shape under 1 mm: a unit that reads metres as millimetres (the grid
    # lies over the surface's own box, so no cell bounds it from below). The
    # sphere is 40 file units across: 0.04 mm at unit 1e-6, 40 mm at the
    # default; one of radius 2 (4 mm across) passes.
    for unit in (1e-6, 1e-9, 1e-30):
        stl_case(f"unit_{unit:g}", ascii_stl(S), ["smaller than 0.001 m", "is `unit` right?"],
                 unit=unit)
    stl_case("ok_sphere_4mm", ascii_stl(sphere(2.0)), [], ok=True)
    stl_case("coordinate_3e38_binary", binary_stl(cube(3e38)), ["larger than 10 m"])
    # The reader's index lists each triangle under every cell of its box: 4000
    # slivers (2000 triangles, each with its flipped twin: closed) whose box is
    # the whole (y, z) extent put 4000 x ~4000 = 1.6e7 pairs in the (y, z)
    # index, above 64 per triangle and 1e7 (a double cone of 65 000 segments
    # overflowed the int offsets). A cylinder of 2000 segments whose caps are
    # fans from their centres (as CAD exports write them) stays well below.
    slivers = [[(0.01 * i, 0.0, 0.0), (0.01 * i + 1.0, 10.0, 10.0), (0.01 * i + 2.0, 10.0, 10.0)]
               for i in range(2000)]
    stl_case("slivers_across_the_index", binary_stl(slivers + flip(slivers)),
             ["long sliver triangles", "remesh"])
    stl_case("ok_cylinder_fan_caps", binary_stl(cylinder_fans(2000)), [], ok=True)
    # Binary files shorter or longer than their count says.
    B = binary_stl(S)
    for name, data, expect in (
            ("binary_cut_record", B[:-25], "not 84 + 50"), ("binary_cut_one", B[:-50], "not 84 + 50"),
            ("binary_header_only", B[:84], "not 84 + 50"), ("binary_83_bytes", B[:83], "too short"),
            ("binary_empty", b"", "too short"), ("binary_extra_byte", B + b"\0", "not 84 + 50"),
            ("count_low", binary_stl(S, count=100), "not 84 + 50 x 100"),
            ("count_high", binary_stl(S, count=len(S) + 1), "not 84 + 50"),
            ("count_max", binary_stl(S, count=2 ** 32 - 1), "not 84 + 50 x 4294967295"),
            ("count_zero", binary_stl([]), "0 triangles"),
            ("binary_solid_cut", binary_stl(S, head=b"solid x")[:-10], "holds binary bytes")):
        stl_case(name, data, [expect])
    for k, v in ((0, NAN), (4, INF), (8, -INF)):
        t = [list(x) for x in S[7]]
        t[k // 3][k % 3] = v
        T = S[:7] + [t] + S[8:]
        stl_case(f"binary_coordinate_{v}", binary_stl(T), ["triangle 7", "not finite"])
    # Sizes: a sparse file whose count matches its size but exceeds the
    # triangle limit; one beyond the byte limit; /dev/zero; FIFOs that do
    # not end where their header says.
    n = 30_000_000
    case("stl/sparse_count_3e7", "stl", "surface",
         sparse("surface.stl", 84 + 50 * n, b"x" * 80 + struct.pack("<I", n)),
         ["limits.max_triangles"])
    case("stl/sparse_5e9_bytes", "stl", "surface", sparse("surface.stl", 5 * 10 ** 9),
         ["limits.max_file_bytes"])
    case("stl/sparse_2e9_zeros", "stl", "surface", sparse("surface.stl", 2 * 10 ** 9),
         ["not 84 + 50 x 0"])
    case("stl/sparse_solid_2e9", "stl", "surface", sparse("surface.stl", 2 * 10 ** 9, b"solid x\n"),
         ["holds binary bytes"])
    case("stl/sparse_solid_text_2e9", "stl", "surface",
         sparse("surface.stl", 2 * 10 ** 9, b"solid x\n" + b" " * 100), ["byte 0x00"])
    case("stl/dev_zero", "stl", "surface", symlink("surface.stl", "/dev/zero"),
         ["goes on after the 84 + 50 x 0"])
    case("stl/fifo_zeros", "stl", "surface", fifo("surface.stl"), ["goes on after"], feed=b"\0",
         feed_bytes=64 << 20)
    case("stl/fifo_binary_short", "stl", "surface", fifo("surface.stl"),
         ["the file ends in triangle 10"], feed=binary_stl(S)[:84 + 500], feed_bytes=584)
    case("stl/fifo_binary_long", "stl", "surface", fifo("surface.stl"), ["goes on after"],
         feed=binary_stl(S) + b"\1" * 100, feed_bytes=len(binary_stl(S)) + 100)
    case("stl/fifo_solid_zeros", "stl", "surface", fifo("surface.stl"), ["goes on after"],
         feed=b"solid x\n" + b"\0" * 4096, feed_bytes=64 << 20)
    case("stl/fifo_ascii_then_binary", "stl", "surface", fifo("surface.stl"), ["byte 0x01"],
         feed=ascii_stl(S)[:-20] + b"\1" * 4096, feed_bytes=1 << 20)
    case("stl/folder", "stl", "surface", folder("surface.stl"), ["cannot read"])
    # ASCII syntax.
    A = ascii_stl(cube()).decode()
    for name, text, expect in (
            ("ascii_nan", A.replace("vertex 10 0 0", "vertex nan 0 0", 1), "got 'nan'"),
            ("ascii_inf", A.replace("vertex 10 0 0", "vertex inf 0 0", 1), "got 'inf'"),
            ("ascii_overflow", A.replace("vertex 10 0 0", "vertex 1e400 0 0", 1), "got '1e400'"),
            ("ascii_comma", A.replace("vertex 10 0 0", "vertex 10,0 0 0", 1), "got '10,0'"),
            ("ascii_two_vertices", A.replace(" vertex 10 0 0\n", "", 1), "expected 'vertex'"),
            ("ascii_four_vertices", A.replace(" endloop", " vertex 1 1 1\n endloop", 1),
             "expected 'endloop'"),
            ("ascii_no_endloop", A.replace(" endloop\n", "", 1), "expected 'endloop'"),
            ("ascii_no_endfacet", A.replace("endfacet\n", "", 1), "expected 'endfacet'"),
            ("ascii_no_endsolid", A.replace("endsolid s\n", ""), "ends before 'endsolid'"),
            ("ascii_after_endsolid", A + "solid t\n", "after 'endsolid'"),
            ("ascii_uppercase", A.replace("facet normal", "FACET NORMAL", 1), "got 'FACET'"),
            ("ascii_misspelt", A.replace("outer loop", "outer lop", 1), "got 'lop'"),
            ("ascii_solid_only", "solid s\n", "ends before 'endsolid'"),
            ("ascii_endsolid_only", "solid s\nendsolid s\n", "0 triangles"),
            ("ascii_nul", A.replace("endloop", "end\0loop", 1), "byte 0x00"),
            ("ascii_control", A.replace("outer", "out\x01er", 1), "byte 0x01"),
            ("ascii_long_word", A.replace("vertex 10 0 0", "vertex " + "9" * 100000 + " 0 0", 1),
             "a word longer than 127 bytes"),
            ("ascii_short", "solid", "ends before 'endsolid'"), ("not_stl", "hello world\n" * 10, "not an ASCII STL"),
    ):
        stl_case(name, text.encode(), [expect])


# ------------------------------------------------------------- templates ----
def make_templates(src):
    hex2 = open(os.path.join(src, "templates", "hex2.tmpl"), "rb").read()
    case("template/ok_hex2_copy", "template", "template", put("t.tmpl", hex2), [], ok=True)
    bad = os.path.join(src, "templates", "bad")
    for f in sorted(os.listdir(bad)):
        case(f"template/shipped_bad_{f[:-5]}", "template", "template",
             put("t.tmpl", open(os.path.join(bad, f), "rb").read()), ["t.tmpl:"])
    for name, data, expect in (
            ("empty", b"", "expected 'template NAME'"),
            ("nul", hex2.replace(b"nodes", b"no\0des", 1), "byte 0x00"),
            ("control", hex2.replace(b"cells", b"ce\x07lls", 1), "byte 0x07"),
            ("bom", b"\xef\xbb\xbf" + hex2, "expected 'template NAME'"),
            ("long_line", hex2.replace(b"\n", b"\n#" + b"x" * 5000 + b"\n", 1), "longer than 4096"),
            ("nodes_zero", hex2.replace(b"nodes 27", b"nodes 0"), "between 1 and 10000"),
            ("nodes_negative", hex2.replace(b"nodes 27", b"nodes -5"), "between 1 and 10000"),
            ("nodes_10001", hex2.replace(b"nodes 27", b"nodes 10001"), "between 1 and 10000"),
            ("nodes_huge", hex2.replace(b"nodes 27", b"nodes 99999999999999"), "between 1 and"),
            ("nodes_float", hex2.replace(b"nodes 27", b"nodes 27.0"), "not a count"),
            ("nodes_more_than_given", hex2.replace(b"nodes 27", b"nodes 28"),
             "expected 3 coordinates"),
            ("cells_more_than_given", hex2.replace(b"cells 8", b"cells 9"), "the file ends after 8"),
            ("node_nan", hex2.replace(b"-1 -1 -1", b"nan -1 -1", 1), "'nan' is not a number"),
            ("node_inf", hex2.replace(b"-1 -1 -1", b"inf -1 -1", 1), "'inf' is not a number"),
            ("index_overflow", first_cell_index(hex2, b"99999999999999999999"), "not a node index"),
            ("index_negative", first_cell_index(hex2, b"-1"), "out of range"),
            ("index_beyond", first_cell_index(hex2, b"27"), "out of range"),
            ("random", np.random.default_rng(2).bytes(2000), "t.tmpl:")):
        case(f"template/{name}", "template", "template", put("t.tmpl", data), [expect])
    case("template/dev_zero", "template", "template", symlink("t.tmpl", "/dev/zero"), ["byte 0x00"])
    case("template/fifo_comments", "template", "template", fifo("t.tmpl"), ["goes on past"],
         feed=b"# a comment line that never ends\n", feed_bytes=64 << 20)
    case("template/sparse_1e9", "template", "template", sparse("t.tmpl", 10 ** 9), ["bytes: a template"])
    case("template/folder", "template", "template", folder("t.tmpl"), ["cannot read the template"])


def first_cell_index(text, value):
    """The template with the first node index of its first cell replaced."""
    lines = text.split(b"\n")
    i = next(k for k, l in enumerate(lines) if l.split()[:1] == [b"cells"]) + 1
    while not lines[i].split() or lines[i].startswith(b"#"):
        i += 1
    lines[i] = b" ".join([value] + lines[i].split()[1:])
    return b"\n".join(lines)


# ----------------------------------------------------------- checkpoints ----
FNV_SEED, FNV_PRIME = 14695981039346656037, 1099511628211


def fnv1a(data, h=FNV_SEED):
    # The checkpoint's checksum (FNV-1a 64, src/sim/checkpoint.c), vectorised by
    # bytes is not possible: plain loop over a short payload.
    for b in data:
        h = ((h ^ b) * FNV_PRIME) & 0xFFFFFFFFFFFFFFFF
    return h


def parse_payload(p):
    """Offsets of the payload's fields (layout of src/sim/checkpoint.c)."""
    o = {"hash": 0, "step": 8, "time": 12, "grid": 20, "origin": 32, "spacing": 56, "n_nodes": 80}
    nn = struct.unpack_from("<i", p, 80)[0]
    o["X"] = 84
    o["n_cells"] = 84 + 24 * nn
    nc = struct.unpack_from("<i", p, o["n_cells"])[0]
    o["cells"] = o["n_cells"] + 4
    o["level"] = o["cells"] + 32 * nc
    o["parent"] = o["level"] + 4 * nc
    o["first_child"] = o["parent"] + 4 * nc
    o["n_children"] = o["first_child"] + 4 * nc
    o["fill"] = o["n_children"] + 4 * nc
    o["u"] = o["fill"] + 8 * nc
    o["v"] = o["u"] + 24 * nn
    o["tools"] = o["v"] + 24 * nn
    tl = struct.unpack_from("<Q", p, o["tools"])[0]
    o["solver"] = o["tools"] + 8 + tl
    sl = struct.unpack_from("<Q", p, o["solver"])[0]
    o["adapt"] = o["solver"] + 8 + sl
    return o, nn, nc


def checkpoint_file(base, mutate=None, header=None):
    """The base checkpoint with its payload changed by mutate(payload,
    offsets) (bytearray, in place), size and checksum made right again; or
    with header(raw) changing the raw bytes after that."""
    raw = bytearray(base)
    payload = bytearray(raw[32:])
    if mutate:
        o, nn, nc = parse_payload(payload)
        mutate(payload, o, nn, nc)
        raw = raw[:16] + struct.pack("<QQ", len(payload), fnv1a(payload)) + payload
    if header:
        raw = header(bytearray(raw))
    return bytes(raw)


def make_checkpoints(binary, work):
    scene = SCENES["restart"]
    base_dir = os.path.join(work, "checkpoint-base")
    shutil.rmtree(base_dir, ignore_errors=True)
    os.makedirs(base_dir)
    with open(os.path.join(base_dir, "scene.yaml"), "w") as f:
        f.write(scene)
    out = os.path.join(base_dir, "out")
    p = subprocess.run([binary, "run", os.path.join(base_dir, "scene.yaml"), "--out", out,
                        "--quiet"], capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError("the base checkpoint's run failed: " + p.stderr)
    base = open(os.path.join(out, "checkpoint.nhc"), "rb").read()
    o, nn, nc = parse_payload(bytearray(base[32:]))
    assert nc > 2, "the base checkpoint's mesh is not refined"

    def ck(name, expect, data=None, writer=None, ok=False):
        def write(d):
            for f in os.listdir(out):  # the run's outputs, which --restart continues
                if f != "checkpoint.nhc":
                    shutil.copy(os.path.join(out, f), d)
            if writer:
                return writer(d)
            with open(os.path.join(d, "checkpoint.nhc"), "wb") as f:
                f.write(data)
            return "checkpoint.nhc"
        case(f"checkpoint/{name}", "checkpoint", "restart", write, expect, ok)

    def at(field, fmt, value, index=0):
        def m(p, o, nn, nc):
            struct.pack_into("<" + fmt, p, o[field] + index * struct.calcsize(fmt), value)
        return m

    ck("ok_copy", [], base, ok=True)
    for n in (0, 7, 31):
        ck(f"cut_{n}", ["not a needlehex checkpoint"], base[:n])
    for n in (32, 100, len(base) - 1):
        ck(f"cut_{n}", ["truncated"], base[:n])
    for n in (1, 1000):
        ck(f"extra_{n}", ["trailing bytes"], base + b"\0" * n)
    ck("magic", ["not a needlehex checkpoint"], b"NHCKPX" + base[6:])
    for v in (0, 9, 2 ** 32 - 1):
        ck(f"version_{v}", [f"format {v}"], base[:8] + struct.pack("<I", v) + base[12:])
    for v in (2, 3, 4, 5, 6, 7):  # an older needlehex's state (no hand-over offsets; 4: no
        # quasi-static prediction; 5: no anchoring errors; 6: no shaft points' axial errors;
        # 7: no goal estimate's state)
        ck(f"version_{v}", [f"format {v}", "older needlehex"],
           base[:8] + struct.pack("<I", v) + base[12:])
    ck("byte_order", ["byte order"], base[:12] + struct.pack(">I", 0x01020304) + base[16:])
    for name, size, expect in (("size_zero", 0, "trailing bytes"),
                               ("size_huge", 2 ** 62, "truncated"),
                               ("size_plus_1", len(base) - 31, "truncated"),
                               ("size_minus_1", len(base) - 33, "trailing bytes")):
        ck(name, [expect], base[:16] + struct.pack("<Q", size) + base[24:])
    ck("checksum", ["checksum mismatch"], base[:24] + bytes([base[24] ^ 1]) + base[25:])
    ck("payload_bit", ["checksum mismatch"], base[:500] + bytes([base[500] ^ 4]) + base[501:])
    ck("other_scene", ["another scene"], checkpoint_file(base, at("hash", "Q", 12345)))
    for name, mut, expect in (
            ("n_nodes_zero", at("n_nodes", "i", 0), "0 nodes"),
            ("n_nodes_negative", at("n_nodes", "i", -1), "-1 nodes"),
            ("n_nodes_max", at("n_nodes", "i", 2 ** 31 - 1), "2147483647 nodes"),
            ("n_cells_zero", at("n_cells", "i", 0), "0 cells"),
            ("n_cells_max", at("n_cells", "i", 2 ** 31 - 1), "2147483647 cells"),
            ("cell_node_negative", at("cells", "i", -1, 5), "node -1 out of"),
            ("cell_node_beyond", at("cells", "i", nn, 9), f"node {nn} out of"),
            ("x_nan", at("X", "d", NAN, 4), "node position is not finite"),
            ("u_inf", at("u", "d", INF, 2), "displacement or velocity"),
            ("v_nan", at("v", "d", NAN, 0), "displacement or velocity"),
            ("fill_2", at("fill", "d", 2.0, 1), "fill 2 outside"),
            ("fill_nan", at("fill", "d", NAN, 0), "fill nan outside"),
            ("level_negative", at("level", "i", -1, 0), "level -1"),
            ("level_99", at("level", "i", 99, nc - 1), "level 99"),
            ("parent_self", at("parent", "i", nc - 1, nc - 1), "parent"),
            ("parent_beyond", at("parent", "i", nc + 5, nc - 1), "parent"),
            ("first_child_beyond", at("first_child", "i", nc, 0), "children"),
            ("n_children_negative", at("n_children", "i", -3, 0), "children"),
            ("grid_zero", at("grid", "i", 0, 1), "grid axis 1"),
            ("grid_huge", at("grid", "i", 1000, 0), "grid"),
            ("spacing_zero", at("spacing", "d", 0.0, 2), "spacing 0"),
            ("spacing_nan", at("spacing", "d", NAN, 0), "spacing nan"),
            ("origin_inf", at("origin", "d", INF, 1), "grid axis 1"),
            ("step_negative", at("step", "i", -4), "step -4"),
            ("time_nan", at("time", "d", NAN), "time nan"),
            ("tools_block_huge", at("tools", "Q", 2 ** 40), "ends early"),
            ("solver_block_huge", lambda p, o, nn, nc: struct.pack_into("<Q", p, o["solver"], 2 ** 40),
             "ends early")):
        ck(name, [expect], checkpoint_file(base, mut))
    ck("payload_extra", ["goes on"], checkpoint_file(base, lambda p, o, nn, nc: p.extend(b"\0" * 8)))
    ck("payload_short", ["ends early"],
       checkpoint_file(base, lambda p, o, nn, nc: p.__delitem__(slice(len(p) - 8, None))))
    ck("dev_zero", ["not a needlehex checkpoint"], writer=symlink("checkpoint.nhc", "/dev/zero"))
    ck("folder", ["a folder"], writer=folder("checkpoint.nhc"))
    ck("missing", ["cannot open the checkpoint"], writer=lambda d: "checkpoint.nhc")


# ------------------------------------------------------------------ main ----
# Controls nibabel refuses although zlib reads them whole (its gzip module
# wants a gzip file and nothing after the stream).
NIBABEL_REFUSES = ("ok_plain_named_gz", "ok_gz_bytes_after")


def check_controls_with_nibabel():
    """The writer's valid images, read by nibabel: the labels and the affine
    the header means (an independent check of the layouts above)."""
    import nibabel as nib
    for c in CASES:
        if c.reader == "nifti" and c.ok and not c.name.endswith(NIBABEL_REFUSES):
            img = nib.load(os.path.join(c.dir, c.file))
            a = np.asanyarray(img.dataobj)
            assert a.shape[:2] == SHAPE[:2], (c.name, a.shape)
            assert set(np.unique(a)) == {0, 1}, (c.name, np.unique(a))
            assert abs(abs(np.linalg.det(img.affine[:3, :3])) - 8) < 1e-9, (c.name, img.affine)


def make_all(out, binary, src):
    del CASES[:]
    make_nifti()
    make_stl()
    make_templates(src)
    if binary:
        make_checkpoints(binary, out)
    for i, c in enumerate(CASES):
        c.dir = os.path.join(out, f"{i:03d}-{c.name.replace('/', '-')}")
        shutil.rmtree(c.dir, ignore_errors=True)
        os.makedirs(c.dir)
        c.file = c.write(c.dir)
        with open(os.path.join(c.dir, "scene.yaml"), "w") as f:
            f.write(SCENES[c.key].format(file=c.file, unit=c.unit) if c.key != "restart"
                    else SCENES["restart"])
    check_controls_with_nibabel()
    return CASES


def write_corpus(cases, corpus):
    """Every case's file that is a small regular file, as a seed of the fuzz
    target of its reader: corpus/{nifti,stl,template,checkpoint}/NNN-NAME.
    A checkpoint's seed is its payload after the scene hash (the target
    writes the header and hash around it: tests/fuzz/fuzz_checkpoint.c)."""
    for c in cases:
        path = os.path.join(c.dir, c.file)
        if os.path.islink(path) or not os.path.isfile(path) or os.path.getsize(path) > 1 << 20:
            continue
        data = open(path, "rb").read()
        if c.reader == "checkpoint":
            data = data[40:]
        os.makedirs(os.path.join(corpus, c.reader), exist_ok=True)
        with open(os.path.join(corpus, c.reader, os.path.basename(c.dir)), "wb") as f:
            f.write(data)


if __name__ == "__main__":
    args = sys.argv[1:]
    opts = {}
    for opt in ("--binary", "--corpus"):
        if opt in args:
            i = args.index(opt)
            opts[opt] = args[i + 1]
            del args[i:i + 2]
    if len(args) != 1:
        sys.exit(__doc__)
    src = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..")
    cases = make_all(args[0], opts.get("--binary"), src)
    if "--corpus" in opts:
        write_corpus(cases, opts["--corpus"])
    by = {}
    for c in cases:
        by.setdefault((c.reader, c.ok), 0)
        by[(c.reader, c.ok)] += 1
    for (reader, ok), n in sorted(by.items()):
        print(f"{reader:10s} {'controls' if ok else 'bad':8s} {n}")
    print(f"total      {len(cases)}")
