"""The fields of one step as numpy arrays, with the mesh they live on.

The service's JSON (``GET /jobs/{id}/fields?mesh=1``) keeps nodal vectors flat and
interleaved (x0, y0, x1, y1, ...) and the mesh as nested lists; here every array has one row
per node or per cell."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@dataclass
class Contact:
    """The contact state at the Γ3 nodes (one entry per contact node).

    ``slip_velocity`` and ``friction_traction`` are signed along the tangent in 2D and
    lengths in 3D, where ``tangential_velocity`` and ``traction`` give the vectors."""

    node: IntArray
    slip_velocity: FloatArray
    friction_traction: FloatArray
    bound: FloatArray
    slipping: npt.NDArray[np.bool_]
    tangential_velocity: Optional[FloatArray] = None
    traction: Optional[FloatArray] = None

    @classmethod
    def from_json(cls, items: List[Mapping[str, Any]]) -> "Contact":
        def col(name: str, dtype: Any) -> Any:
            return np.array([c[name] for c in items], dtype=dtype)

        vectors = bool(items) and "tangential_velocity" in items[0]
        return cls(
            node=col("node", np.int64),
            slip_velocity=col("slip_velocity", np.float64),
            friction_traction=col("friction_traction", np.float64),
            bound=col("bound", np.float64),
            slipping=col("slipping", np.bool_),
            tangential_velocity=col("tangential_velocity", np.float64).reshape(-1, 3)
            if vectors
            else None,
            traction=col("traction", np.float64).reshape(-1, 3) if vectors else None,
        )


@dataclass
class Fields:
    """One step of a simulation: step number ``n`` (0 is the initial state), time ``t``, the
    requested fields and, when asked for, the mesh.

    Shapes, with N nodes, M cells and d = ``dim`` (2 or 3): ``nodes`` (N, d); ``triangles``
    (M, 3) in 2D or ``tetrahedra`` (M, 4) in 3D; ``u``, ``w`` (N, d); ``zeta`` (N,);
    ``sigma`` (M, 3) as (xx, yy, xy) in 2D, (M, 6) as (xx, yy, zz, xy, yz, xz) in 3D;
    ``von_mises`` (M,). ``boundary`` holds the boundary facets (edges (F, 2) in 2D, faces
    (F, 3) in 3D), ``boundary_part`` their part index into ``parts`` (-1: traction-free) and,
    in 3D, ``boundary_cell`` the tetrahedron each face bounds.

    On the boundary surface of a 3D job (``surface`` true, from ``Job.fields(surface=True)``)
    the mesh is the surface alone: ``nodes`` (S, 3) are the surface nodes, ``node_ids`` (S,)
    their indices in the whole mesh, ``boundary`` (F, 3) the surface triangles in the surface
    numbering (counter-clockwise seen from outside) with ``boundary_part`` and
    ``boundary_cell``, and ``tetrahedra`` is None; ``u``, ``w`` (S, 3) and ``zeta`` (S,) are
    at the surface nodes, ``sigma`` (F, 6) and ``von_mises`` (F,) one per triangle (its
    tetrahedron's), and the contact nodes are numbered as the surface nodes."""

    job: str
    n: int
    t: float
    dim: Optional[int] = None
    nodes: Optional[FloatArray] = None
    triangles: Optional[IntArray] = None
    tetrahedra: Optional[IntArray] = None
    boundary: Optional[IntArray] = None
    boundary_part: Optional[IntArray] = None
    boundary_cell: Optional[IntArray] = None
    parts: List[Dict[str, Any]] = field(default_factory=list)
    surface: bool = False
    node_ids: Optional[IntArray] = None
    u: Optional[FloatArray] = None
    w: Optional[FloatArray] = None
    zeta: Optional[FloatArray] = None
    sigma: Optional[FloatArray] = None
    von_mises: Optional[FloatArray] = None
    contact: Optional[Contact] = None

    def __repr__(self) -> str:
        """One line: the step, its time and the shape of each array present (not the
        arrays themselves, which can hold millions of numbers)."""
        parts = [f"job={self.job!r}", f"n={self.n}", f"t={self.t:g}", f"dim={self.dim}"]
        if self.surface:
            parts.append("surface")
        for name in (
            "nodes", "node_ids", "triangles", "tetrahedra", "boundary", "boundary_part",
            "boundary_cell", "u", "w", "zeta", "sigma", "von_mises",
        ):
            a = getattr(self, name)
            if a is not None:
                parts.append(f"{name}={tuple(a.shape)}")
        if self.parts:
            parts.append(f"parts={len(self.parts)}")
        if self.contact is not None:
            parts.append(f"contact={len(self.contact.node)} nodes")
        return f"Fields({', '.join(parts)})"

    @property
    def cells(self) -> Optional[IntArray]:
        """The triangles or the tetrahedra, whichever the mesh has."""
        return self.triangles if self.triangles is not None else self.tetrahedra

    @classmethod
    def from_json(cls, doc: Mapping[str, Any], dim: Optional[int] = None) -> "Fields":
        """The document of ``GET /jobs/{id}/fields``; ``dim`` is needed only to shape
        vectors of a document with neither mesh, nor sigma, nor zeta."""
        mesh = doc.get("mesh")
        out = cls(job=str(doc.get("job", "")), n=int(doc["n"]), t=float(doc["t"]))
        if mesh is not None:
            dim = int(mesh["dim"])
            out.nodes = np.asarray(mesh["nodes"], dtype=np.float64).reshape(-1, dim)
            out.parts = [dict(p) for p in mesh.get("parts", [])]
            if mesh.get("surface"):
                out.surface = True
                out.node_ids = np.asarray(mesh["node_ids"], dtype=np.int64)
                out.boundary = np.asarray(mesh["triangles"], dtype=np.int64).reshape(-1, 3)
                out.boundary_cell = np.asarray(mesh["cells"], dtype=np.int64)
                facets = [(None, p) for p in mesh["triangle_parts"]]
            elif dim == 2:
                out.triangles = np.asarray(mesh["triangles"], dtype=np.int64).reshape(-1, 3)
                facets = mesh["boundary_edges"]
                out.boundary = np.asarray([f[0] for f in facets], dtype=np.int64).reshape(-1, 2)
            else:
                out.tetrahedra = np.asarray(mesh["tetrahedra"], dtype=np.int64).reshape(-1, 4)
                facets = mesh["boundary_faces"]
                out.boundary = np.asarray([f[0] for f in facets], dtype=np.int64).reshape(-1, 3)
                out.boundary_cell = np.asarray([f[2] for f in facets], dtype=np.int64)
            out.boundary_part = np.asarray(
                [-1 if f[1] is None else f[1] for f in facets], dtype=np.int64
            )
        if "sigma" in doc:
            out.sigma = np.asarray(doc["sigma"], dtype=np.float64)
            if out.sigma.ndim != 2:
                out.sigma = out.sigma.reshape(0, 3)
            if dim is None and len(out.sigma):
                dim = 3 if out.sigma.shape[1] == 6 else 2
        if dim is None and "zeta" in doc and "u" in doc and doc["zeta"]:
            dim = len(doc["u"]) // len(doc["zeta"])
        out.dim = dim
        for name in ("u", "w"):
            if name in doc:
                flat = np.asarray(doc[name], dtype=np.float64)
                setattr(out, name, flat.reshape(-1, dim) if dim else flat)
        if "zeta" in doc:
            out.zeta = np.asarray(doc["zeta"], dtype=np.float64)
        if "von_mises" in doc:
            out.von_mises = np.asarray(doc["von_mises"], dtype=np.float64)
        if "contact" in doc:
            out.contact = Contact.from_json(doc["contact"])
        return out
