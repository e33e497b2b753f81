"""The service's VTU files read by VTK itself (the library ParaView is built on, from its
wheel): cell types, array names and components, and values equal to the fields JSON, for a 2D
and a 3D job; the archive's PVD names files that VTK reads offline; the zlib-compressed files
(the default) read by VTK and by meshio equal to the raw ones."""

from __future__ import annotations

import os
import tarfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from contact_sim import Client

try:
    from vtkmodules import vtkIOXML as vtk_xml
    from vtkmodules.util import numpy_support
except ImportError:
    # CI installs it (the client's "test" extra); elsewhere the check is optional.
    if os.environ.get("CI"):
        raise
    pytest.skip("VTK is not installed (pip install vtk)", allow_module_level=True)

VTK_TRIANGLE, VTK_TETRA = 5, 10

try:
    import meshio
except ImportError:
    # CI installs it (the client's "all" extra); elsewhere the check is skipped.
    if os.environ.get("CI"):
        raise
    meshio = None


def vtk_to_numpy(array: Any) -> np.ndarray:
    out: np.ndarray = numpy_support.vtk_to_numpy(array)  # type: ignore[no-untyped-call]
    return out


def read_vtu(path: Path) -> Any:
    reader = vtk_xml.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0, f"VTK could not read {path}"
    return reader.GetOutput()


def arrays(data: Any) -> dict[str, np.ndarray]:
    return {
        data.GetArrayName(i): vtk_to_numpy(data.GetArray(i)) for i in range(data.GetNumberOfArrays())
    }


@pytest.mark.parametrize(
    "preset,h,cell_type,dim",
    [("paper-exp3", "1/4", VTK_TRIANGLE, 2), ("box-exp3", "1/4", VTK_TETRA, 3)],
)
def test_vtk_reads_the_vtu_of_every_dimension(
    client: Client, tmp_path: Path, preset: str, h: str, cell_type: int, dim: int
) -> None:
    job = client.submit(preset, overrides={"h": h, "k": "1/4"}).wait(progress=False)
    f = job.fields()
    assert f.nodes is not None and f.cells is not None and f.u is not None
    path = tmp_path / "last.vtu"
    path.write_bytes(job.vtu())
    grid = read_vtu(path)
    assert grid.GetNumberOfPoints() == len(f.nodes)
    assert grid.GetNumberOfCells() == len(f.cells)
    assert {grid.GetCellType(i) for i in range(grid.GetNumberOfCells())} == {cell_type}
    points = vtk_to_numpy(grid.GetPoints().GetData())
    assert np.array_equal(points[:, :dim], f.nodes)
    for c in (0, len(f.cells) // 2, len(f.cells) - 1):
        ids = grid.GetCell(c).GetPointIds()
        assert [ids.GetId(i) for i in range(ids.GetNumberOfIds())] == list(f.cells[c])
    point = arrays(grid.GetPointData())
    cell = arrays(grid.GetCellData())
    assert point["u"].shape == (len(f.nodes), 3) and point["w"].shape == (len(f.nodes), 3)
    assert np.array_equal(point["u"][:, :dim], f.u)
    assert f.zeta is not None and np.array_equal(point["zeta"], f.zeta)
    assert {"contact_state", "slip_velocity"} <= set(point)
    assert cell["sigma"].shape == (len(f.cells), 6)
    assert f.von_mises is not None and np.array_equal(cell["von_mises"], f.von_mises)


def test_the_archive_pvd_resolves_offline_to_vtu_files_vtk_reads(
    client: Client, tmp_path: Path
) -> None:
    # VTK's wheel has no PVD reader (ParaView's is its own): the collection is parsed here and
    # every file it names is read by VTK from the extracted archive, with no server.
    job = client.submit("box-exp3", overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    f = job.fields()
    assert f.cells is not None and f.zeta is not None
    with tarfile.open(job.download(tmp_path)) as tar:
        tar.extractall(tmp_path / "x", filter="data")
    (pvd,) = (tmp_path / "x").rglob("*.pvd")
    root = ET.parse(pvd).getroot()
    assert root.get("type") == "Collection"
    entries = [(float(d.get("timestep", "nan")), d.get("file", "")) for d in root.iter("DataSet")]
    times = [t for t, _ in entries]
    assert len(entries) >= 2 and times == sorted(times)
    assert times[0] == 0.0 and abs(times[-1] - 1.0) < 1e-12
    for _, name in entries:
        assert not name.startswith(("/", "http")), name
        grid = read_vtu(pvd.parent / name)
        assert grid.GetNumberOfCells() == len(f.cells)
    last = read_vtu(pvd.parent / entries[-1][1])
    assert np.array_equal(vtk_to_numpy(last.GetPointData().GetArray("zeta")), f.zeta)


@pytest.mark.parametrize("preset,dim", [("paper-exp3", 2), ("box-exp3", 3)])
def test_zlib_compressed_vtu_reads_back_equal_to_raw(
    client: Client, tmp_path: Path, preset: str, dim: int
) -> None:
    job = client.submit(preset, overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    zlib, raw = tmp_path / "zlib.vtu", tmp_path / "raw.vtu"
    zlib.write_bytes(job.vtu(compression="zlib"))
    raw.write_bytes(job.vtu(compression="none"))
    root = ET.parse(zlib).getroot()
    assert root.get("compressor") == "vtkZLibDataCompressor"
    assert ET.parse(raw).getroot().get("compressor") is None
    assert zlib.stat().st_size < raw.stat().st_size

    # VTK: the same points, cells and every point and cell array, bit for bit.
    z, r = read_vtu(zlib), read_vtu(raw)
    assert np.array_equal(
        vtk_to_numpy(z.GetPoints().GetData()), vtk_to_numpy(r.GetPoints().GetData())
    )
    assert np.array_equal(
        vtk_to_numpy(z.GetCells().GetConnectivityArray()),
        vtk_to_numpy(r.GetCells().GetConnectivityArray()),
    )
    for data in ("GetPointData", "GetCellData", "GetFieldData"):
        za, ra = arrays(getattr(z, data)()), arrays(getattr(r, data)())
        assert za.keys() == ra.keys() and za
        for name in za:
            assert np.array_equal(za[name], ra[name]), name

    # meshio: the same mesh and data.
    if meshio is None:
        pytest.skip("meshio is not installed (pip install meshio)")
    mz, mr = meshio.read(zlib), meshio.read(raw)
    assert np.array_equal(mz.points, mr.points)
    assert [c.type for c in mz.cells] == [c.type for c in mr.cells] == [
        "triangle" if dim == 2 else "tetra"
    ]
    assert np.array_equal(mz.cells[0].data, mr.cells[0].data)
    assert mz.point_data.keys() == mr.point_data.keys() and "zeta" in mz.point_data
    for name in mz.point_data:
        assert np.array_equal(mz.point_data[name], mr.point_data[name]), name
    for name in mz.cell_data:
        assert np.array_equal(mz.cell_data[name][0], mr.cell_data[name][0]), name
    zeta = job.fields().zeta
    assert zeta is not None and np.array_equal(mz.point_data["zeta"], zeta)
