"""Generate the committed test meshes of contact-core's gmsh MSH 4.1 reader (src/msh/).

Run once, from this directory, with the `gmsh` Python wheel (headless, no GUI needed):

    python3 -m venv /tmp/gmsh-venv && /tmp/gmsh-venv/bin/pip install gmsh
    /tmp/gmsh-venv/bin/python generate.py

It writes plate-with-hole.msh and arch-on-support.msh, which the presets embed, into
../../preset-meshes/, and the others next to this script:

- plate-with-hole.msh         2D, ASCII MSH 4.1: the plate [0, 2] x [0, 1] with a hole of
                              radius 0.2 centred at (0.7, 0.45); line groups "clamped" (x = 0),
                              "contact" (y = 0), "traction" (y = 1), "hole"; surface group "body".
- plate-with-hole-binary.msh  the same mesh written as binary MSH 4.1.
- arch-on-support.msh         2D, ASCII MSH 4.1: the annulus sector 1 <= r <= 1.5,
                              0 <= angle <= 120 degrees; line groups "contact" (inner arc),
                              "clamped" (the straight end on y = 0), "outer", "free-end";
                              surface group "body".
- cylinder.msh                3D, ASCII MSH 4.1: radius 0.5, height 1, base on z = 0;
                              triangle groups "base", "top", "side"; volume group "body".

Fixed options (random seed, meshing algorithms, sizes) make the output reproducible for a given
gmsh version (the committed files come from gmsh 4.15.2). Tests read the committed files and
never run gmsh.
"""

import math
import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
PRESETS = os.path.join(HERE, "..", "..", "preset-meshes")


def start(name):
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("Mesh.RandomSeed", 1)
    gmsh.option.setNumber("Mesh.Algorithm", 6)  # Frontal-Delaunay (2D)
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay (3D)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.model.add(name)


def write(name, binary=False, folder=HERE):
    gmsh.option.setNumber("Mesh.Binary", 1 if binary else 0)
    gmsh.write(os.path.join(folder, name))


def group(dim, tags, name):
    gmsh.model.addPhysicalGroup(dim, tags, name=name)


def plate_with_hole():
    start("plate-with-hole")
    geo = gmsh.model.geo
    h = 0.1
    p = [geo.addPoint(x, y, 0, h) for x, y in [(0, 0), (2, 0), (2, 1), (0, 1)]]
    bottom = geo.addLine(p[0], p[1])
    right = geo.addLine(p[1], p[2])
    top = geo.addLine(p[2], p[3])
    left = geo.addLine(p[3], p[0])
    cx, cy, r = 0.7, 0.45, 0.2
    c = geo.addPoint(cx, cy, 0, h)
    q = [geo.addPoint(cx + r * math.cos(a), cy + r * math.sin(a), 0, h / 2)
         for a in (0, math.pi / 2, math.pi, 3 * math.pi / 2)]
    arcs = [geo.addCircleArc(q[i], c, q[(i + 1) % 4]) for i in range(4)]
    outer = geo.addCurveLoop([bottom, right, top, left])
    hole = geo.addCurveLoop(arcs)
    surface = geo.addPlaneSurface([outer, hole])
    geo.synchronize()
    group(1, [left], "clamped")
    group(1, [bottom], "contact")
    group(1, [top], "traction")
    group(1, [right], "free")
    group(1, arcs, "hole")
    group(2, [surface], "body")
    gmsh.model.mesh.generate(2)
    write("plate-with-hole.msh", folder=PRESETS)
    write("plate-with-hole-binary.msh", binary=True)
    gmsh.finalize()


def arch_on_support():
    start("arch-on-support")
    geo = gmsh.model.geo
    h = 0.08
    r0, r1, a = 1.0, 1.5, 2 * math.pi / 3
    c = geo.addPoint(0, 0, 0, h)
    i0 = geo.addPoint(r0, 0, 0, h)
    o0 = geo.addPoint(r1, 0, 0, h)
    i1 = geo.addPoint(r0 * math.cos(a), r0 * math.sin(a), 0, h)
    o1 = geo.addPoint(r1 * math.cos(a), r1 * math.sin(a), 0, h)
    end0 = geo.addLine(i0, o0)
    outer = geo.addCircleArc(o0, c, o1)
    end1 = geo.addLine(o1, i1)
    inner = geo.addCircleArc(i1, c, i0)
    loop = geo.addCurveLoop([end0, outer, end1, inner])
    surface = geo.addPlaneSurface([loop])
    geo.synchronize()
    group(1, [end0], "clamped")
    group(1, [inner], "contact")
    group(1, [outer], "outer")
    group(1, [end1], "free-end")
    group(2, [surface], "body")
    gmsh.model.mesh.generate(2)
    write("arch-on-support.msh", folder=PRESETS)
    gmsh.finalize()


def cylinder():
    start("cylinder")
    occ = gmsh.model.occ
    volume = occ.addCylinder(0, 0, 0, 0, 0, 1, 0.5)
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.15)
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.15)
    base, top, side = [], [], []
    for dim, tag in gmsh.model.getBoundary([(3, volume)], oriented=False):
        x, y, z = gmsh.model.occ.getCenterOfMass(dim, tag)
        if abs(z) < 1e-9:
            base.append(tag)
        elif abs(z - 1) < 1e-9:
            top.append(tag)
        else:
            side.append(tag)
    group(2, base, "base")
    group(2, top, "top")
    group(2, side, "side")
    group(3, [volume], "body")
    gmsh.model.mesh.generate(3)
    write("cylinder.msh")
    gmsh.finalize()


if __name__ == "__main__":
    plate_with_hole()
    arch_on_support()
    cylinder()
