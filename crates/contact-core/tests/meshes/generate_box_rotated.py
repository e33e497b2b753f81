"""Generate box-rotated.msh: the Kuhn box of contact-core's Mesh::<3>::cuboid, moved rigidly.

The box [0, 2] x [0, 1] x [0, 1] at n = 4 cells per unit length (8 x 4 x 4 cubes, 6
tetrahedra each), built EXACTLY as `Mesh::<3>::cuboid(2.0, 1.0, 1.0, 8, 4, 4)` builds it
(crates/contact-core/src/mesh/cuboid.rs): the same node order, cell order and vertex order
within each cell; then every node x is mapped to R x + t, R the rotation about the axis
(1, 2, 3)/sqrt(14) by 0.7 rad, t = (0.3, -0.2, 0.5). A scene run on this file and on the
cuboid must give the same norms (rotation-invariant quantities) up to round-off.

Physical triangle groups (of the box before it is moved): "clamped" (the x = 0 face),
"contact" (z = 0), "load" (the z = 1 and x = 2 faces); the volume group "body". The y = 0 and
y = 1 faces are in no group (traction-free). The group triangles are the boundary faces of the
tetrahedra, in the order of the cells and, within a cell, of the faces opposite vertex 3, 2,
1, 0; their vertices are ordered so that the outward normal follows them.

ASCII MSH 4.1 with 17 significant digits. No gmsh needed: run with any Python 3,

    python3 generate_box_rotated.py

R and t as the tests copy them (row-major; x_file = R x_box + t):

    R = [[0.78163917390702509, -0.48292928421421222, 0.39473979817379978],
         [0.55011723070435836, 0.83203013377463464, -0.071392499417875857],
         [-0.29395787843858057, 0.27295633888831428, 0.91601506688731726]]
    t = [0.3, -0.2, 0.5]
"""

import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))

LX, LY, LZ = 2.0, 1.0, 1.0
NX, NY, NZ = 8, 4, 4

# The rotation and translation, written out so that the file does not depend on this
# machine's trigonometric functions; checked against Rodrigues' formula below.
R = [
    [0.78163917390702509, -0.48292928421421222, 0.39473979817379978],
    [0.55011723070435836, 0.83203013377463464, -0.071392499417875857],
    [-0.29395787843858057, 0.27295633888831428, 0.91601506688731726],
]
T = [0.3, -0.2, 0.5]
AXIS = [1.0, 2.0, 3.0]
ANGLE = 0.7

# The axis orders of the 6 Kuhn paths of a cube, in cell order (cuboid.rs KUHN_PATHS), and
# which of them are odd permutations (their vertices 1 and 2 are swapped).
KUHN_PATHS = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
ODD = {1, 2, 5}


def check_rotation():
    norm = math.sqrt(sum(a * a for a in AXIS))
    n = [a / norm for a in AXIS]
    c, s = math.cos(ANGLE), math.sin(ANGLE)
    k = [[0.0, -n[2], n[1]], [n[2], 0.0, -n[0]], [-n[1], n[0], 0.0]]
    for i in range(3):
        for j in range(3):
            exact = c * (i == j) + s * k[i][j] + (1 - c) * n[i] * n[j]
            assert abs(exact - R[i][j]) < 1e-15, (i, j, exact, R[i][j])


def node(i, j, k):
    return i + (NX + 1) * (j + (NY + 1) * k)


def lattice():
    """The integer lattice indices of the nodes, and the cells, as cuboid() makes them."""
    index = []
    for k in range(NZ + 1):
        for j in range(NY + 1):
            for i in range(NX + 1):
                index.append((i, j, k))
    step = [1, NX + 1, (NX + 1) * (NY + 1)]
    cells = []
    for k in range(NZ):
        for j in range(NY):
            for i in range(NX):
                v000 = node(i, j, k)
                v111 = v000 + step[0] + step[1] + step[2]
                for p, (a, b, _) in enumerate(KUHN_PATHS):
                    v1 = v000 + step[a]
                    v2 = v1 + step[b]
                    if p in ODD:
                        cells.append((v000, v2, v1, v111))
                    else:
                        cells.append((v000, v1, v2, v111))
    return index, cells


def coordinates(index):
    """The box's nodes: i*lx/nx evaluated as (i*lx)/nx, as cuboid() does in f64."""
    return [(i * LX / NX, j * LY / NY, k * LZ / NZ) for i, j, k in index]


def det3(a, b, c):
    return (a[0] * (b[1] * c[2] - b[2] * c[1])
            - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))


def groups(index, cells, x):
    """The boundary triangles of each group, outward-ordered (on the unmoved box)."""
    faces = {  # group -> list of (axis, lattice value) box faces
        "clamped": [(0, 0)],
        "contact": [(2, 0)],
        "load": [(2, NZ), (0, NX)],
    }
    out = {name: [] for name in faces}
    for cell in cells:
        for opposite in (3, 2, 1, 0):
            tri = [v for a, v in enumerate(cell) if a != opposite]
            for name, planes in faces.items():
                if any(all(index[v][axis] == value for v in tri) for axis, value in planes):
                    p, q, r = (x[v] for v in tri)
                    o = x[cell[opposite]]
                    sub = lambda u, w: [u[c] - w[c] for c in range(3)]
                    # Positive when the opposite vertex is on the side the normal points to.
                    if det3(sub(q, p), sub(r, p), sub(o, p)) > 0:
                        tri[1], tri[2] = tri[2], tri[1]
                    out[name].append(tuple(tri))
    return out


def moved(p):
    return tuple(sum(R[r][c] * p[c] for c in range(3)) + T[r] for r in range(3))


def main():
    check_rotation()
    index, cells = lattice()
    x = coordinates(index)
    for cell in cells:
        a, b, c, d = (x[v] for v in cell)
        sub = lambda u, w: [u[k] - w[k] for k in range(3)]
        assert det3(sub(b, a), sub(c, a), sub(d, a)) > 0
    tris = groups(index, cells, x)
    assert [len(tris[g]) for g in ("clamped", "contact", "load")] == [
        2 * NY * NZ, 2 * NX * NY, 2 * NX * NY + 2 * NY * NZ]
    y = [moved(p) for p in x]
    g = lambda v: "%.17g" % v

    def box(nodes):
        """The bounding box of the moved nodes, as an entity line writes it."""
        lo = [min(y[v][c] for v in nodes) for c in range(3)]
        hi = [max(y[v][c] for v in nodes) for c in range(3)]
        return " ".join(g(v) for v in lo + hi)

    surface_blocks = [
        (1, tris["clamped"]),
        (2, tris["contact"]),
        # The load group's faces on z = 1 (surface 3) and x = 2 (surface 4).
        (3, [t for t in tris["load"] if all(index[v][2] == NZ for v in t)]),
        (4, [t for t in tris["load"] if not all(index[v][2] == NZ for v in t)]),
    ]
    assert sum(len(b) for _, b in surface_blocks[2:]) == len(tris["load"])
    surface_box = {e: box({v for t in b for v in t}) for e, b in surface_blocks}
    lines = [
        "$MeshFormat", "4.1 0 8", "$EndMeshFormat",
        "$Comments",
        "The Kuhn box Mesh::<3>::cuboid(2.0, 1.0, 1.0, 8, 4, 4) moved by x -> R x + t,",
        "R the rotation about (1, 2, 3)/sqrt(14) by 0.7 rad, t = (0.3, -0.2, 0.5);",
        "written by generate_box_rotated.py. R row-major:",
    ]
    lines += [" ".join(g(v) for v in row) for row in R]
    lines += ["t: " + " ".join(g(v) for v in T), "$EndComments"]
    lines += [
        "$PhysicalNames", "4",
        '2 1 "clamped"', '2 2 "contact"', '2 3 "load"', '3 4 "body"',
        "$EndPhysicalNames",
        # Surfaces 1-4 carry the groups (the load group has two faces); the volume is bounded
        # by them (the traction-free y faces have no elements and no entity).
        "$Entities", "0 0 4 1",
        "1 %s 1 1 0" % surface_box[1],
        "2 %s 1 2 0" % surface_box[2],
        "3 %s 1 3 0" % surface_box[3],
        "4 %s 1 3 0" % surface_box[4],
        "1 %s 1 4 4 1 2 3 4" % box(range(len(y))),
        "$EndEntities",
    ]
    n = len(y)
    lines += ["$Nodes", "1 %d 1 %d" % (n, n), "3 1 0 %d" % n]
    lines += [str(v + 1) for v in range(n)]
    lines += [" ".join(g(v) for v in p) for p in y]
    lines += ["$EndNodes"]
    total = sum(len(b) for _, b in surface_blocks) + len(cells)
    lines += ["$Elements", "%d %d 1 %d" % (len(surface_blocks) + 1, total, total)]
    tag = 0
    for entity, block in surface_blocks:
        lines.append("2 %d 2 %d" % (entity, len(block)))
        for t in block:
            tag += 1
            lines.append(" ".join(str(v) for v in (tag,) + tuple(v + 1 for v in t)))
    lines.append("3 1 4 %d" % len(cells))
    for c in cells:
        tag += 1
        lines.append(" ".join(str(v) for v in (tag,) + tuple(v + 1 for v in c)))
    lines += ["$EndElements"]
    with open(os.path.join(HERE, "box-rotated.msh"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
