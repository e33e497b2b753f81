"""Generate the MSH 2.2 test files of contact-core's reader (src/msh/v2.rs) with gmsh itself.

Run once, from any directory, with the `gmsh` Python wheel (headless, no GUI needed):

    python3 -m venv /tmp/gmsh-venv && /tmp/gmsh-venv/bin/pip install gmsh
    /tmp/gmsh-venv/bin/python generate_msh22.py

It writes, next to this script:

- plate-with-hole-msh22.msh         ../../preset-meshes/plate-with-hole.msh re-saved by gmsh as
                                    ASCII MSH 2.2 (the same nodes, elements and groups);
- plate-with-hole-msh22-binary.msh  the same as binary MSH 2.2;
- cylinder-msh22-binary.msh         cylinder.msh re-saved as binary MSH 2.2 (3D);
- square-order2-msh22.msh           the unit square meshed with 6-node (second-order) triangles,
                                    ASCII MSH 2.2: refused by name;
- square-quads.msh                  the unit square meshed with quadrangles (recombined),
                                    ASCII MSH 4.1: refused by name.

The committed files come from gmsh 4.15.2. Tests read them and never run gmsh.
"""

import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
PRESETS = os.path.join(HERE, "..", "..", "preset-meshes")


def resave(source, target, version, binary):
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.open(source)
    gmsh.option.setNumber("Mesh.MshFileVersion", version)
    gmsh.option.setNumber("Mesh.Binary", 1 if binary else 0)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.write(os.path.join(HERE, target))
    gmsh.finalize()


def square(target, version, order=1, recombine=False):
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("Mesh.RandomSeed", 1)
    gmsh.model.add("square")
    s = gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
    gmsh.model.occ.synchronize()
    gmsh.model.addPhysicalGroup(1, [1], name="bottom")
    gmsh.model.addPhysicalGroup(2, [s], name="body")
    gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
    if recombine:
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.model.mesh.generate(2)
    if order > 1:
        gmsh.model.mesh.setOrder(order)
    gmsh.option.setNumber("Mesh.MshFileVersion", version)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.write(os.path.join(HERE, target))
    gmsh.finalize()


if __name__ == "__main__":
    plate = os.path.join(PRESETS, "plate-with-hole.msh")
    resave(plate, "plate-with-hole-msh22.msh", 2.2, False)
    resave(plate, "plate-with-hole-msh22-binary.msh", 2.2, True)
    resave(os.path.join(HERE, "cylinder.msh"), "cylinder-msh22-binary.msh", 2.2, True)
    square("square-order2-msh22.msh", 2.2, order=2)
    square("square-quads.msh", 4.1, recombine=True)
