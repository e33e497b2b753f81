"""The client against the real service (see conftest.py). Each test submits scenes of its
own (distinct h, k), since a scene identical to one already computed is answered with the
existing job."""

from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
import tarfile
import time
from pathlib import Path

import numpy as np
import pytest

from contact_sim import ApiError, Client, Job, JobCancelled, JobFailed, ServiceUnreachable
from contact_sim._sse import events
from conftest import MESHES, REPO, serve


def rectangle_counts(width: int, height: int, h: int) -> tuple[int, int, int]:
    """Nodes, triangles and boundary edges of the diagonal pattern on (0,width)×(0,height)
    with 1/h cells per unit length: every square cut in two."""
    nx, ny = width * h, height * h
    return (nx + 1) * (ny + 1), 2 * nx * ny, 2 * (nx + ny)


def test_lifecycle_submit_wait_results_list_delete(
    client: Client, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    job = client.submit("paper-exp2", overrides={"h": "1/4", "k": "1/4"})
    assert job.kind == "simulation" and job.status in ("queued", "running", "succeeded")
    assert job.wait(progress=True, timeout=60) is job
    assert job.status == "succeeded"
    # The tqdm bar went to stderr and reached the job's 4 steps.
    assert "4/4" in capfd.readouterr().err

    summary = job.summary()
    assert summary["time"]["steps"] == 4 and summary["mesh"]["h"] == 0.25
    assert [s["n"] for s in summary["steps"]] == [1, 2, 3, 4]

    nodes, triangles, edges = rectangle_counts(2, 1, 4)
    f = job.fields()
    assert (f.n, f.t, f.dim) == (4, 1.0, 2)
    assert f.nodes is not None and f.nodes.shape == (nodes, 2)
    assert f.triangles is not None and f.triangles.shape == (triangles, 3)
    assert f.tetrahedra is None and f.cells is f.triangles
    assert f.u is not None and f.u.shape == (nodes, 2)
    assert f.w is not None and f.w.shape == (nodes, 2)
    assert f.zeta is not None and f.zeta.shape == (nodes,)
    assert f.sigma is not None and f.sigma.shape == (triangles, 3)
    assert f.von_mises is not None and f.von_mises.shape == (triangles,)
    assert f.boundary is not None and f.boundary.shape == (edges, 2)
    assert f.boundary_part is not None and f.boundary_part.shape == (edges,)
    # The body is clamped on x = 0: no displacement there, some elsewhere.
    clamped = f.nodes[:, 0] == 0.0
    assert clamped.sum() == 5 and np.all(f.u[clamped] == 0.0) and np.abs(f.u).max() > 0
    kinds = {f.parts[p]["type"] for p in f.boundary_part[f.nodes[f.boundary[:, 0], 0] == 0.0]}
    assert "clamped" in kinds
    # Contact on [0, 1] × {0}: the contact nodes lie there.
    assert f.contact is not None
    assert np.all(f.nodes[f.contact.node, 1] == 0.0) and np.all(f.nodes[f.contact.node, 0] <= 1)
    # The norms of the summary are the fields' own: ζ_min at T.
    assert f.zeta.min() == pytest.approx(summary["final"]["zeta_min"], rel=1e-12)

    # Step 0 is the initial state: w = 0, ζ = ζ0 = 1; a subset without the mesh.
    f0 = job.fields(step=0, names=["w", "zeta"], mesh=False)
    assert f0.n == 0 and f0.nodes is None and f0.u is None
    assert f0.w is not None and f0.w.shape == (nodes, 2) and not f0.w.any()
    assert f0.zeta is not None and np.all(f0.zeta == 1.0)

    archive = job.download(tmp_path)
    assert archive == tmp_path / f"contact-sim-{job.id}.tar"
    with tarfile.open(archive) as tar:
        names = set(tar.getnames())
        expected = {f"{job.id}/{n}" for n in ("scene.json", "summary.json", "result.pvd")}
        expected |= {f"{job.id}/fields/step_{n:06}.vtu" for n in range(5)}
        assert names == expected
        member = tar.extractfile(f"{job.id}/summary.json")
        assert member is not None and json.load(member) == summary
    assert job.download(f"{tmp_path}/new/") == tmp_path / "new" / archive.name
    with tarfile.open(tmp_path / "new" / archive.name) as tar:
        assert set(tar.getnames()) == expected
    assert job.download(tmp_path / "named.tar") == tmp_path / "named.tar"

    # The same scene again is answered with the finished job; an idempotency key gives the
    # same job on every retry.
    assert client.submit("paper-exp2", overrides={"h": "1/4", "k": "1/4"}).id == job.id
    keyed = client.submit("paper-exp2", {"h": "1/4", "k": "1/2"}, idempotency_key="lifecycle-1")
    assert client.submit("paper-exp2", {"h": "1/4", "k": "1/2"}, idempotency_key="lifecycle-1") == keyed
    keyed.wait(progress=False, timeout=60)

    # Listing one job a page walks every page, each job once.
    listed = [j.id for j in client.jobs(page_size=1)]
    assert len(listed) == len(set(listed)) and {job.id, keyed.id} <= set(listed)
    assert listed == [j.id for j in client.jobs(page_size=500)]
    assert job.id in {j.id for j in client.jobs(status="succeeded")}
    assert job.id not in {j.id for j in client.jobs(status="failed")}

    job.delete()
    with pytest.raises(ApiError) as e:
        client.job(job.id)
    assert e.value.status == 404


def test_invalid_requests_raise_problems_with_pointers(client: Client) -> None:
    with pytest.raises(ApiError) as e:
        client.submit("paper-exp2", overrides={"h": "-1", "k": "abc"})
    err = e.value
    assert err.status == 422 and err.type == "/problems/invalid-scene"
    assert dict(err.errors).keys() == {"/overrides/h", "/overrides/k"}
    assert "must be > 0" in dict(err.errors)["/overrides/h"]
    assert err.problem["status"] == 422
    # Printed one error a line, pointer first.
    text = str(err)
    assert text.splitlines()[0].startswith("422 invalid scene: the scene has 2 errors")
    for pointer, message in err.errors:
        assert any(
            line.split() and line.split()[0] == pointer and line.endswith(message)
            for line in text.splitlines()[1:]
        )

    with pytest.raises(ApiError) as e:
        client.submit({"material": 1})
    assert {"/domain", "/time", "/material"} <= dict(e.value.errors).keys()

    with pytest.raises(ApiError) as e:
        client.submit("no-such-preset")
    assert e.value.status == 422 and dict(e.value.errors).keys() == {"/preset"}

    # A file name is a file, not a preset: a missing one says so.
    for missing in ("missing.json", "scenes/missing", "MISSING.JSON"):
        with pytest.raises(FileNotFoundError, match=f"no such file: {missing}"):
            client.submit(missing)

    with pytest.raises(ApiError) as e:
        client.job("00000000-0000-0000-0000-000000000000")
    assert e.value.status == 404 and e.value.errors == []

    with pytest.raises(ValueError):
        client.submit({"domain": {}}, overrides={"h": "1/8"})


def test_a_scene_file_is_submitted_by_its_path(client: Client, tmp_path: Path) -> None:
    path = tmp_path / "exp2.json"
    path.write_text(json.dumps({"preset": "paper-exp2", "overrides": {"h": "1/4", "k": "1/4"}}))
    by_path = client.submit(str(path)).wait(progress=False)
    by_name = client.submit("paper-exp2", overrides={"h": "1/4", "k": "1/4"})
    assert by_path.status == "succeeded" and by_name.id == by_path.id


def test_problem_of_a_response_that_is_not_json() -> None:
    err = ApiError.from_response(502, "text/html", b"<html>Bad Gateway</html>", 3.0)
    assert (err.status, err.errors, err.retry_after) == (502, [], 3.0)
    assert "Bad Gateway" in str(err)


def test_a_failed_job_raises_its_problem(client: Client) -> None:
    problem = {
        "type": "/problems/smallness",
        "title": "smallness condition",
        "status": 422,
        "detail": "the smallness condition (2.31) fails",
        "errors": [{"pointer": "/friction", "message": "c2τ·cτ² ≥ m_A"}],
    }
    job = Job(client, {"id": "j1", "status": "failed", "error": problem})
    with pytest.raises(JobFailed) as e:
        job._check()
    assert (e.value.job_id, e.value.status, e.value.type) == ("j1", 422, "/problems/smallness")
    assert e.value.errors == [("/friction", "c2τ·cτ² ≥ m_A")]
    assert str(e.value).startswith("job j1 failed: 422 smallness condition")
    with pytest.raises(JobCancelled):
        Job(client, {"id": "j2", "status": "cancelled"})._check()


def test_submissions_refused_for_rate_are_retried(tmp_path: Path) -> None:
    # One submission a second, no burst: the second and third are refused with 429 and
    # Retry-After, and go through when retried.
    data = tmp_path / "data"
    with serve(data, "--workers", "1", "--submit-rate", "1", "--submit-burst", "1") as url:
        statuses: list[int] = []
        with Client(url) as c:
            c._http.event_hooks["response"].append(lambda r: statuses.append(r.status_code))
            jobs = [c.submit("paper-exp1", {"h": "1/2", "k": f"1/{n}"}) for n in (2, 4, 8)]
            assert len({j.id for j in jobs}) == 3
            assert 429 in statuses and statuses.count(202) == 3
        # Without retries the refusal is the caller's: two submissions within a second
        # cannot both pass a bucket of one.
        with Client(url, retries=0) as c, pytest.raises(ApiError) as e:
            for k in ("1/16", "1/32"):
                c.submit("paper-exp1", {"h": "1/2", "k": k})
        assert e.value.status == 429 and e.value.retry_after is not None


def test_server_sent_events_framing() -> None:
    stream = [
        ": keep-alive\n",
        "event: progress\r\n",
        'data: {"step": 1}\n',
        "\n",
        "data: a\n",
        "data:b\n",
        "\n",
        "event: status\n",
        'data: {"step": 2',  # cut off by the end of the stream
    ]
    got = [(e.event, e.data) for e in events(stream)]
    assert got == [("progress", '{"step": 1}'), ("message", "a\nb")]


def wait_until_running(job: Job, timeout: float = 30) -> None:
    deadline = time.monotonic() + timeout
    while job.refresh().progress.get("step", 0) < 1:
        assert time.monotonic() < deadline, job.resource
        time.sleep(0.05)


def test_cancel_a_running_job(client: Client) -> None:
    # 4,225 nodes and 4,096 steps (the last one stored): far longer than the test waits.
    scene = client.preset("paper-convergence")
    scene["mesh"]["h"], scene["time"]["k"] = "1/64", "1/4096"
    scene["output"] = {"every": 4096}
    job = client.submit(scene)
    wait_until_running(job)
    assert job.status == "running"
    with pytest.raises(ApiError) as e:
        job.delete()
    assert e.value.status == 409
    assert job.cancel() is job and job.status in ("running", "cancelled")
    with pytest.raises(JobCancelled):
        job.wait(progress=False, timeout=30)
    assert job.status == "cancelled"
    assert 1 <= job.progress["step"] < job.progress["steps"] == 4096
    with pytest.raises(ApiError) as e:
        job.fields()
    assert e.value.status == 409
    job.delete()


def test_wait_follows_the_event_stream_or_polls(client: Client) -> None:
    requests: list[str] = []
    client._http.event_hooks["request"].append(
        lambda r: requests.append(f"{r.method} {r.url.path} {r.headers.get('if-none-match', '')}")
    )
    streamed = client.submit("paper-exp3", overrides={"h": "1/8", "k": "1/32"})
    requests.clear()
    streamed.wait(progress=False, timeout=60)
    assert streamed.status == "succeeded" and streamed.progress["step"] == 32
    # One stream to the end, then the final resource once.
    path = f"/jobs/{streamed.id}"
    assert requests == [f"GET {path}/events ", f"GET {path} "]

    # Long enough (2,145 nodes, 256 steps) to be polled more than once.
    polled = client.submit("paper-exp3", overrides={"h": "1/32", "k": "1/256"})
    requests.clear()
    polled.wait(progress=False, events=False, timeout=60)
    assert polled.status == "succeeded" and polled.progress["step"] == 256
    path = f"/jobs/{polled.id}"
    assert len(requests) >= 2 and all(r.startswith(f"GET {path} ") for r in requests)
    # Every poll after the first one sends the ETag it was given.
    assert requests[0] == f"GET {path} " and all(r != f"GET {path} " for r in requests[1:])


def test_mesh_upload_and_a_job_on_it(client: Client, tmp_path: Path) -> None:
    path = MESHES / "plate-with-hole.msh"
    mesh_id = client.upload_mesh(path)
    assert mesh_id == hashlib.sha256(path.read_bytes()).hexdigest()
    assert client.upload_mesh(path) == mesh_id
    info = client.mesh(mesh_id)
    assert info["bytes"] == path.stat().st_size and info["summary"]["dimension"] == 2
    assert mesh_id in {m["id"] for m in client.meshes(page_size=1)}

    scene = client.preset("plate-with-hole")
    scene["domain"] = {"mesh": mesh_id}
    scene["time"]["k"] = "1/4"
    job = client.submit(scene).wait(progress=False, timeout=60)
    f = job.fields()
    assert f.nodes is not None and f.triangles is not None
    assert f.nodes.shape == (info["summary"]["nodes"], 2)
    assert f.triangles.shape == (info["summary"]["cells"], 3)
    assert f.boundary is not None and len(f.boundary) == info["summary"]["boundary_facets"]
    assert {p.get("group") for p in f.parts} == {"clamped", "contact", "traction"}

    bad = tmp_path / "bad.msh"
    bad.write_text("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n")
    with pytest.raises(ApiError) as e:
        client.upload_mesh(bad)
    assert e.value.status == 422 and e.value.detail


def test_a_study_preset_is_submitted_by_name(client: Client) -> None:
    job = client.submit("paper-table-2")
    assert job.kind == "study"
    with pytest.raises(ValueError):
        client.submit("paper-table-1", overrides={"h": "1/4"})
    # A scene preset's name still submits the scene.
    assert client.submit("paper-exp1", overrides={"h": "1/4", "k": "1/4"}).kind == "simulation"
    if job.refresh().status in ("queued", "running"):
        job.cancel()
    # The adaptive study preset runs as an adaptive study.
    adaptive = client.submit("l-bracket-adaptive").wait(timeout=180, progress=False)
    s = adaptive.summary()
    assert s["kind"] == "adapt" and s["reached"] and s["cycles"][-1]["estimate"] <= 0.15


def test_a_target_study_gives_the_chosen_run(client: Client) -> None:
    job = client.target("paper-convergence", 0.2, quantity="w").wait(timeout=120, progress=False)
    s = job.summary()
    assert s["kind"] == "target"
    assert s["chosen"]["estimated_error"] <= 0.2
    f = job.fields()
    assert f.w is not None and len(f.w) > 0


def test_a_target_study_may_take_an_adaptive_mesh(client: Client) -> None:
    # The l-bracket's re-entrant corner: an adaptive mesh with fewer nodes than the uniform
    # level that passed its check, and an estimate no larger, is taken and served.
    job = client.target("l-bracket", 0.1, meshes="auto").wait(timeout=180, progress=False)
    s = job.summary()
    m = s["meshes"]
    assert m["policy"] == "auto" and m["taken"] == "adaptive", m["reason"]
    last = m["cycles"][-1]
    assert last["nodes"] < m["uniform_nodes"]
    assert s["run"]["mesh"]["nodes"] == last["nodes"]
    mesh = client.mesh(s["final_mesh"]["id"])
    assert mesh["summary"]["nodes"] == last["nodes"]
    w = job.fields().w
    assert w is not None and w.size == 2 * last["nodes"]
    # Adaptive meshes are compared by the velocity's estimate: not for u.
    with pytest.raises(ApiError) as e:
        client.target("l-bracket", 0.1, quantity="u", meshes="auto")
    assert e.value.status == 422


def test_an_adaptive_study_as_a_dataframe(client: Client) -> None:
    scene = client.preset("l-bracket")
    scene["mesh"]["h"] = "1/4"
    scene["time"] = {"t_end": 0.25, "k": "1/16"}
    scene["output"] = {"every": 0, "last": True, "fields": ["w"]}
    job = client.adapt(scene, target=0.01, max_cycles=3, reference_refine=2)
    df = job.wait(progress=False, timeout=120).adapt_table()
    cycles = df[df["run"] == "cycle"]
    assert list(cycles["index"]) == [0, 1, 2]
    assert cycles["nodes"].is_monotonic_increasing
    assert cycles["estimate"].is_monotonic_decreasing and cycles["error"].is_monotonic_decreasing
    assert df.attrs["stopped"] == "max_cycles" and not df.attrs["reached"]
    assert (df["run"] == "reference").sum() == 1
    # The last cycle is served as a simulation on the final mesh, an uploaded mesh of ours.
    mesh = client.mesh(df.attrs["final_mesh"]["id"])
    assert mesh["summary"]["nodes"] == cycles["nodes"].iloc[-1]
    w = job.fields().w
    assert w is not None and w.size == 2 * cycles["nodes"].iloc[-1]


def test_study_table_as_dataframe(client: Client) -> None:
    study = {
        "study": {
            "scene": "paper-convergence",
            "h": ["1/2", "1/4", "1/8"],
            "k": "1/16",
            "reference": {"h": "1/16", "k": "1/16"},
        }
    }
    job = client.submit(study)
    assert job.kind == "study"
    df = job.wait(progress=False, timeout=60).table()
    assert list(df["h"]) == [0.5, 0.25, 0.125] and list(df["k"]) == [1 / 16] * 3
    assert {"err_w", "err_zeta", "order_w", "unknowns", "velocity_iterations_max"} <= set(df)
    # The errors fall as h does, and each order is the slope between neighbouring rows.
    assert df["err_w"].is_monotonic_decreasing and df["err_zeta"].is_monotonic_decreasing
    assert math.isnan(df["order_w"][0])
    for i in (1, 2):
        slope = math.log(df["err_w"][i - 1] / df["err_w"][i]) / math.log(2)
        assert df["order_w"][i] == pytest.approx(slope, rel=1e-9)
    assert df.attrs["reference"]["h"] == 1 / 16 and df.attrs["vary"] == "h"
    # h and k also as the fractions the study was written in, next to the floats.
    assert list(df["h_fraction"]) == ["1/2", "1/4", "1/8"]
    assert list(df["k_fraction"]) == ["1/16"] * 3
    cols = list(df.columns)
    assert cols.index("h_fraction") == cols.index("h") + 1
    text = job.table_text()
    assert all(h in text for h in ("1/2", "1/4", "1/8"))
    assert job.report_svg().lstrip().startswith("<")
    with pytest.raises(ApiError) as e:
        job.fields()
    assert e.value.status == 404
    with pytest.raises(ValueError):
        client.submit("paper-exp1", {"h": "1/4", "k": "1/4"}).wait(progress=False).table()


def test_vtu_read_back_by_meshio(client: Client) -> None:
    job = client.submit("paper-exp3", overrides={"h": "1/4", "k": "1/8"}).wait(progress=False)
    nodes, triangles, _ = rectangle_counts(2, 1, 4)
    f = job.fields()
    assert f.triangles is not None
    for step, ref in (("last", f), (0, job.fields(step=0))):
        m = job.to_meshio(step)
        assert m.points.shape == (nodes, 3) and not m.points[:, 2].any()
        assert list(m.cells_dict) == ["triangle"]
        assert np.array_equal(m.cells_dict["triangle"], f.triangles)
        assert m.point_data["u"].shape == (nodes, 3) and m.point_data["w"].shape == (nodes, 3)
        assert m.point_data["zeta"].shape == (nodes,)
        assert m.cell_data["sigma"][0].shape == (triangles, 6)
        assert m.cell_data["von_mises"][0].shape == (triangles,)
        assert ref.u is not None and ref.zeta is not None and ref.sigma is not None
        assert np.array_equal(m.point_data["u"][:, :2], ref.u)
        assert np.array_equal(m.point_data["zeta"], ref.zeta)
        # VTK's order xx, yy, zz, xy, yz, xz; the plane model has no zz, yz, xz.
        six = m.cell_data["sigma"][0]
        assert np.array_equal(six[:, [0, 1, 3]], ref.sigma) and not six[:, [2, 4, 5]].any()
        assert m.field_data["Step"][0] == ref.n


def test_3d_job_fields_and_vtu(client: Client) -> None:
    job = client.submit("box-exp3", overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    # The box (0,2)×(0,1)×(0,1) at h = 1/4: 8×4×4 cubes of 6 tetrahedra; 2 triangles on each
    # boundary square.
    nx, ny, nz = 8, 4, 4
    nodes, tets = (nx + 1) * (ny + 1) * (nz + 1), 6 * nx * ny * nz
    faces = 2 * 2 * (nx * ny + ny * nz + nx * nz)
    f = job.fields()
    assert f.dim == 3 and f.triangles is None and f.cells is f.tetrahedra
    assert f.nodes is not None and f.nodes.shape == (nodes, 3)
    assert f.tetrahedra is not None and f.tetrahedra.shape == (tets, 4)
    assert f.u is not None and f.u.shape == (nodes, 3)
    assert f.w is not None and f.w.shape == (nodes, 3)
    assert f.zeta is not None and f.zeta.shape == (nodes,)
    assert f.sigma is not None and f.sigma.shape == (tets, 6)
    assert f.von_mises is not None and f.von_mises.shape == (tets,)
    assert f.boundary is not None and f.boundary.shape == (faces, 3)
    assert f.boundary_cell is not None and f.boundary_cell.shape == (faces,)
    # Each boundary face is a face of the tetrahedron named with it.
    for face, cell in zip(f.boundary, f.boundary_cell):
        assert set(face) <= set(f.tetrahedra[cell])
    c = f.contact
    assert c is not None and c.traction is not None and c.tangential_velocity is not None
    assert c.traction.shape == c.tangential_velocity.shape == (len(c.node), 3)
    assert np.all(f.nodes[c.node, 2] == 0.0)  # Γ3 is the bottom z = 0
    # Vectors without the mesh are shaped all the same.
    u_only = job.fields(names=["u"], mesh=False)
    assert u_only.u is not None and np.array_equal(u_only.u, f.u)

    m = job.to_meshio()
    assert m.points.shape == (nodes, 3) and list(m.cells_dict) == ["tetra"]
    assert np.array_equal(m.cells_dict["tetra"], f.tetrahedra)
    assert np.array_equal(m.point_data["u"], f.u)
    assert np.array_equal(m.cell_data["sigma"][0], f.sigma)


def test_3d_surface_fields_are_the_full_fields_on_the_boundary(client: Client) -> None:
    job = client.submit("box-exp3", overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    # The box (0,2)×(0,1)×(0,1) at h = 1/4: 8×4×4 cubes; 2 triangles on each boundary
    # square, and every node but the (nx−1)(ny−1)(nz−1) interior ones.
    nx, ny, nz = 8, 4, 4
    faces = 2 * 2 * (nx * ny + ny * nz + nx * nz)
    surface_nodes = (nx + 1) * (ny + 1) * (nz + 1) - (nx - 1) * (ny - 1) * (nz - 1)
    s = job.fields(surface=True)
    full = job.fields()
    assert s.surface and not full.surface and s.tetrahedra is None
    assert s.nodes is not None and s.nodes.shape == (surface_nodes, 3)
    assert s.node_ids is not None and s.node_ids.shape == (surface_nodes,)
    assert s.boundary is not None and s.boundary.shape == (faces, 3)
    assert s.boundary_cell is not None and s.boundary_part is not None
    assert full.nodes is not None and full.tetrahedra is not None
    assert np.array_equal(s.nodes, full.nodes[s.node_ids])
    # The surface nodes are those on a face of the box.
    lo, hi = full.nodes.min(axis=0), full.nodes.max(axis=0)
    on_box = np.flatnonzero(((full.nodes == lo) | (full.nodes == hi)).any(axis=1))
    assert np.array_equal(s.node_ids, on_box)
    for name in ("u", "w"):
        assert np.array_equal(getattr(s, name), getattr(full, name)[s.node_ids])
    assert s.zeta is not None and full.zeta is not None
    assert np.array_equal(s.zeta, full.zeta[s.node_ids])
    assert s.von_mises is not None and full.von_mises is not None
    assert np.array_equal(s.von_mises, full.von_mises[s.boundary_cell])
    assert s.sigma is not None and full.sigma is not None
    assert np.array_equal(s.sigma, full.sigma[s.boundary_cell])
    # Each triangle is a face of its tetrahedron, in the whole mesh's numbering.
    for tri, cell in zip(s.node_ids[s.boundary], s.boundary_cell):
        assert set(tri) <= set(full.tetrahedra[cell])
    c, fc = s.contact, full.contact
    assert c is not None and fc is not None
    assert np.array_equal(s.node_ids[c.node], fc.node)
    assert np.array_equal(c.slip_velocity, fc.slip_velocity)
    # Without the mesh, the fields are on the surface all the same.
    u_only = job.fields(names=["u"], mesh=False, surface=True)
    assert u_only.u is not None and s.u is not None and np.array_equal(u_only.u, s.u)
    # A 2D job's fields are whole with or without surface.
    plane = client.submit("paper-exp2", overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    a, b = plane.fields(surface=True), plane.fields()
    assert not a.surface and a.triangles is not None and b.triangles is not None
    assert a.u is not None and b.u is not None
    assert np.array_equal(a.triangles, b.triangles) and np.array_equal(a.u, b.u)


def test_token_is_sent_as_bearer(server_url: str) -> None:
    seen: list[str] = []
    with Client(server_url, token="s3cret") as c:
        c._http.event_hooks["request"].append(
            lambda r: seen.append(r.headers.get("authorization", ""))
        )
        assert c.health()["status"] == "ok"
        assert [p["name"] for p in c.presets()][:1] == ["paper-exp1"]
    assert seen == ["Bearer s3cret"] * 2
    with Client(server_url) as c:
        assert "authorization" not in c._http.headers


def test_readme_from_python_lines_run(
    server_url: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme.split("\n### From Python\n", 1)[1].split("\n## ", 1)[0]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    assert len(code.strip().splitlines()) == 8
    assert "http://127.0.0.1:8080" in code
    monkeypatch.chdir(tmp_path)
    scope: dict[str, object] = {}
    exec(compile(code.replace("http://127.0.0.1:8080", server_url), "README.md", "exec"), scope)
    job = scope["job"]
    assert isinstance(job, Job) and job.status == "succeeded"
    nodes, triangles, _ = rectangle_counts(2, 1, 16)
    f = scope["f"]
    assert f.nodes.shape == (nodes, 2) and f.triangles.shape == (triangles, 3)  # type: ignore[attr-defined]
    assert (tmp_path / f"contact-sim-{job.id}.tar").stat().st_size > 0
    scope["client"].close()  # type: ignore[attr-defined]


def test_convergence_example_writes_its_plot(server_url: str, tmp_path: Path) -> None:
    """examples/convergence.py end to end: Table 1 (the reference run at h = k = 1/128 takes
    ~12 s on the debug server)."""
    out = tmp_path / "table1.png"
    script = Path(__file__).resolve().parents[1] / "examples" / "convergence.py"
    run = subprocess.run(
        [sys.executable, str(script), "--url", server_url, "--out", str(out), "--no-progress"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    # The paper's Table 1 orders at h = 1/32 as README reports them: w 0.869, ζ 1.590.
    last = [line.split() for line in run.stdout.splitlines() if line.strip().startswith("1/32")]
    assert len(last) == 1
    assert (round(float(last[0][2]), 3), round(float(last[0][4]), 3)) == (0.869, 1.590)


def test_fields_repr_is_one_line_of_shapes(client: Client) -> None:
    job = client.submit("paper-exp2", overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    f = job.fields()
    text = repr(f)
    nodes, triangles, _ = rectangle_counts(2, 1, 4)
    assert "\n" not in text and len(text) < 400, text
    assert f"nodes=({nodes}, 2)" in text and f"triangles=({triangles}, 3)" in text
    assert f"zeta=({nodes},)" in text and "array(" not in text


def test_download_honours_the_umask(client: Client, tmp_path: Path) -> None:
    import os

    job = client.submit("paper-exp2", overrides={"h": "1/4", "k": "1/4"}).wait(progress=False)
    old = os.umask(0o027)
    try:
        path = job.download(tmp_path)
    finally:
        os.umask(old)
    # A new file of this user: 0666 less the umask 027.
    assert path.stat().st_mode & 0o777 == 0o640


def test_a_wrong_url_raises_an_error_naming_it(tmp_path: Path) -> None:
    import socket

    # A port nothing listens on: bound, then closed.
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"http://127.0.0.1:{port}"
    with Client(url, retries=0, timeout=5) as c:
        with pytest.raises(ServiceUnreachable) as e:
            c.submit("paper-exp1")
        assert url in str(e.value) and e.value.url == url
        assert isinstance(e.value, ConnectionError)
    with pytest.raises(ValueError, match="127.0.0.1:8080"):
        Client("127.0.0.1:8080")


def test_a_server_that_is_not_the_service_is_named(tmp_path: Path) -> None:
    import functools
    import http.server
    import threading

    # Another web server at the URL: its HTML refusal names the URL that answered.
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(tmp_path))
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    url = f"http://127.0.0.1:{httpd.server_address[1]}"
    try:
        with Client(url, retries=0) as c:
            with pytest.raises(ApiError) as e:
                c.submit("paper-exp1")
    finally:
        httpd.shutdown()
        httpd.server_close()
    assert f"(from {url}/" in str(e.value) and "contact-sim service" in str(e.value)


def test_examples_help_shows_defaults() -> None:
    examples = Path(__file__).resolve().parents[1] / "examples"
    for script in sorted(examples.glob("*.py")):
        run = subprocess.run(
            [sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=60
        )
        assert run.returncode == 0, run.stderr
        assert "(default: http://127.0.0.1:8080)" in run.stdout, run.stdout


def test_continue_a_finished_job(client: Client) -> None:
    # paper-convergence at h = k = 1/4 with a low Tresca bound (Γ3 slips): 2 steps, then on to
    # t = 1; the same 4 steps as one run to t = 1, bit for bit (direct path).
    scene = client.preset("paper-convergence")
    scene["mesh"]["h"] = "1/4"
    scene["time"] = {"t_end": "1/2", "k": "1/4"}
    scene["friction"] = {"law": "tresca", "g": 0.05}
    scene["solver"] = {"linear": "direct"}
    parent = client.submit(scene).wait(progress=False, timeout=60)
    child = client.continue_(parent, t_end=1).wait(progress=False, timeout=60)
    summary = child.summary()
    assert summary["continued_from"]["job"] == parent.id
    assert summary["continued_from"]["step"] == 2
    assert [s["n"] for s in summary["steps"]] == [1, 2, 3, 4]
    straight = dict(scene, time={"t_end": 1, "k": "1/4"})
    one = client.submit(straight).wait(progress=False, timeout=60)
    steps = one.summary()["steps"]
    assert [s["w_V"] for s in summary["steps"]] == [s["w_V"] for s in steps]
    assert any(s["slip_nodes"] > 0 for s in steps)
    cu, ou = child.fields(step=4).u, one.fields(step=4).u
    assert cu is not None and ou is not None and cu.tolist() == ou.tolist()
    # The same continuation again is the same job; a string id works as the Job does.
    assert client.continue_(parent.id, t_end=1) == child
    # Another friction from t = 1/2 on: a job of its own.
    slower = dict(scene, friction={"law": "tresca", "g": 1})
    other = client.continue_(parent, t_end=1, scene=slower).wait(progress=False, timeout=60)
    assert other != child and other.summary()["continued_from"]["job"] == parent.id
    # Refused: a changed mesh, and a job that is not finished.
    with pytest.raises(ApiError) as e:
        client.continue_(parent, t_end=1, scene=dict(scene, mesh={"h": "1/8"}))
    assert e.value.status == 422 and e.value.errors[0][0] == "/continue/scene/mesh"
    with pytest.raises(ApiError) as e:
        client.continue_("00000000-0000-4000-8000-000000000000", t_end=1)
    assert e.value.status == 422 and e.value.errors[0][0] == "/continue/job"


def test_a_sweep_as_a_dataframe(client: Client) -> None:
    # paper-convergence at h = k = 1/4 to t = 1/2: a 3 × 2 sweep of the Tresca bound and κ,
    # one member already computed as a job (taken from it, not computed again).
    scene = client.preset("paper-convergence")
    scene["mesh"]["h"] = "1/4"
    scene["time"] = {"t_end": "1/2", "k": "1/4"}
    scene["friction"] = {"law": "tresca", "g": 1}
    scene["solver"] = {"linear": "direct"}
    done = dict(scene, friction={"law": "tresca", "g": 0.05})
    first = client.submit(done).wait(progress=False, timeout=60)
    one = first.summary()
    df = client.sweep(
        scene, {"/friction/g": [0.05, 1, 2], "/damage/kappa": [0.5, 0.1]}, progress=False, timeout=60
    )
    assert list(df["/friction/g"]) == [0.05, 0.05, 1, 1, 2, 2]
    assert list(df["/damage/kappa"]) == [0.5, 0.1] * 3
    assert {"w_V", "zeta_min", "min_zeta", "slip_nodes", "max_slip_speed", "wall_s"} <= set(df)
    assert list(df["cached"]) == [True, False, False, False, False, False]
    assert df.attrs["computed"] == 5 and df.attrs["mode"] == "grid"
    assert df["w_V"][0] == one["final"]["w_V"] and df["slip_nodes"][0] > 0
    # Every member is a job: the one taken is the earlier job, the others are the sweep's.
    assert df["job"][0] == first.id
    assert client.job(df["job"][1]).resource["links"]["sweep"] == f"/jobs/{df.attrs['job']}"
    job = client.job(df.attrs["job"])
    assert job.sweep_table().equals(df)
    with pytest.raises(ApiError) as e:
        client.sweep(scene, {"/friction/g": [-1]}, progress=False)
    assert e.value.status == 422 and e.value.errors[0][0] == "/sweep/vary/~1friction~1g"
