"""Generate part.msh (beside this script, not committed): the imported tetrahedral part of the
speed benchmark (issue "real meshes on every core"; docs/src/speed).

A 2 × 1 × 1 block (x, y, z) with a cylindrical hole along y (radius 0.2, axis through
x = 1.3, z = 0.5) and a notch cut into its top (0.1 wide in x at x = 0.7, 0.35 deep, through
in y). Tetrahedra; physical surface groups "clamped" (x = 0), "bottom" (z = 0, the contact
face) and "top" (z = 1, loaded), and the volume group "body". ASCII MSH 4.1.

    python3 -m venv target/gmsh-venv && target/gmsh-venv/bin/pip install gmsh
    target/gmsh-venv/bin/python benches/part/generate_part.py [SIZE]

SIZE (default 0.0255) is gmsh's target edge length: 0.0255 gives about 80,000 nodes with gmsh
4.15. Fixed options (random seed, algorithms) make the output reproducible for one gmsh
version. Tests never run gmsh; the bench reads the file this script writes.
"""

import os
import sys

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    size = float(sys.argv[1]) if len(sys.argv) > 1 else 0.0255
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("Mesh.RandomSeed", 1)
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    gmsh.option.setNumber("Mesh.Algorithm3D", 10)  # HXT (parallel Delaunay)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.model.add("part")
    occ = gmsh.model.occ
    block = occ.addBox(0, 0, 0, 2, 1, 1)
    hole = occ.addCylinder(1.3, 0, 0.5, 0, 1, 0, 0.2)
    notch = occ.addBox(0.65, 0, 0.65, 0.1, 1, 0.35)
    cut, _ = occ.cut([(3, block)], [(3, hole), (3, notch)])
    occ.synchronize()
    assert len(cut) == 1
    volume = cut[0][1]
    gmsh.option.setNumber("Mesh.MeshSizeMin", size)
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    groups = {"clamped": [], "bottom": [], "top": []}
    for _, tag in gmsh.model.getBoundary([(3, volume)], oriented=False):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
        if x1 < 1e-5:
            groups["clamped"].append(tag)
        elif z1 < 1e-5:
            groups["bottom"].append(tag)
        elif z0 > 1 - 1e-5:
            groups["top"].append(tag)
    assert all(groups.values()), groups
    for name, tags in groups.items():
        gmsh.model.addPhysicalGroup(2, tags, name=name)
    gmsh.model.addPhysicalGroup(3, [volume], name="body")
    gmsh.model.mesh.generate(3)
    nodes = len(gmsh.model.mesh.getNodes()[0])
    gmsh.write(os.path.join(HERE, "part.msh"))
    gmsh.finalize()
    print(f"part.msh: {nodes} nodes")


if __name__ == "__main__":
    main()
