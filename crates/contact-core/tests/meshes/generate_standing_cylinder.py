"""Generate ../../preset-meshes/standing-cylinder.msh: the body of the standing-cylinder preset
and of contact-core's solid tests.

The cylinder of radius 0.5 and height 1.5 standing on its base: axis z, base on z = 0, top on
z = 1.5. Tetrahedra; physical triangle groups "base" (z = 0), "top" (z = 1.5) and "side"
(the curved surface), and the volume group "body". ASCII MSH 4.1.

It is not cylinder.msh (radius 0.5, height 1, written by generate.py), which the reader's and
the service's tests already pin down.

Run once, from any directory, with the `gmsh` Python wheel (headless, no GUI needed):

    python3 -m venv /work/venv-gmsh && /work/venv-gmsh/bin/pip install gmsh numpy
    /work/venv-gmsh/bin/python generate_standing_cylinder.py

Fixed options (random seed, meshing algorithms, sizes) make the output reproducible for a given
gmsh version (the committed file comes from gmsh 4.15.2). Tests read the committed file and
never run gmsh.
"""

import os

import gmsh

HERE = os.path.dirname(os.path.abspath(__file__))
RADIUS = 0.5
HEIGHT = 1.5
# Gives about 2,500 nodes with gmsh 4.15.2.
SIZE = 0.08


def main():
    gmsh.initialize()
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("Mesh.RandomSeed", 1)
    gmsh.option.setNumber("Mesh.Algorithm", 6)  # Frontal-Delaunay (surfaces)
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay (volume)
    gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
    gmsh.option.setNumber("Mesh.SaveAll", 0)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.model.add("standing-cylinder")
    occ = gmsh.model.occ
    volume = occ.addCylinder(0, 0, 0, 0, 0, HEIGHT, RADIUS)
    occ.synchronize()
    gmsh.option.setNumber("Mesh.MeshSizeMin", SIZE)
    gmsh.option.setNumber("Mesh.MeshSizeMax", SIZE)
    base, top, side = [], [], []
    for _, tag in gmsh.model.getBoundary([(3, volume)], oriented=False):
        z = occ.getCenterOfMass(2, tag)[2]
        if abs(z) < 1e-9:
            base.append(tag)
        elif abs(z - HEIGHT) < 1e-9:
            top.append(tag)
        else:
            side.append(tag)
    assert base and top and side
    gmsh.model.addPhysicalGroup(2, base, name="base")
    gmsh.model.addPhysicalGroup(2, top, name="top")
    gmsh.model.addPhysicalGroup(2, side, name="side")
    gmsh.model.addPhysicalGroup(3, [volume], name="body")
    gmsh.model.mesh.generate(3)
    gmsh.write(os.path.join(HERE, "..", "..", "preset-meshes", "standing-cylinder.msh"))
    gmsh.finalize()


if __name__ == "__main__":
    main()
