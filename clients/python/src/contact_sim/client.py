"""The client: one :class:`Client` per service, a :class:`Job` per submitted simulation or
study. Every URL, query parameter and shape is the one of the service's contract
(``api/openapi.yaml``, also served at ``GET /openapi.yaml``)."""

from __future__ import annotations

import email.utils
import json
import os
import tempfile
import time
from fractions import Fraction
from pathlib import Path
from typing import (
    TYPE_CHECKING,
    Any,
    Dict,
    Iterator,
    List,
    Mapping,
    Optional,
    Sequence,
    Union,
)

import httpx

from . import _sse
from .errors import ApiError, JobCancelled, JobFailed, ServiceUnreachable
from .fields import Fields

if TYPE_CHECKING:  # optional extras, imported where used
    import meshio
    import pandas

__all__ = ["Client", "Job"]

__version__ = "0.1.0"

#: A preset name, a scene / preset request / study request document, or a JSON file of one.
Submission = Union[str, Mapping[str, Any], "os.PathLike[str]"]
#: h, k or T (t_end): a number, a ratio string ("1/32") or a Fraction.
Ratio = Union[int, float, str, Fraction]

FINISHED = frozenset({"succeeded", "failed", "cancelled"})


def _is_path(s: str) -> bool:
    """Whether a submitted string names a file rather than a preset: preset names are words
    with hyphens, never ``.json`` names or paths."""
    return s.lower().endswith(".json") or "/" in s or os.sep in s


def _ratio(v: Ratio) -> Union[int, float, str]:
    if isinstance(v, Fraction):
        return f"{v.numerator}/{v.denominator}"
    return v


def _retry_after(r: httpx.Response) -> Optional[float]:
    """Seconds of a Retry-After header (delay-seconds or an HTTP date)."""
    value = r.headers.get("retry-after")
    if value is None:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return None
    return max(0.0, when.timestamp() - time.time())


def _error(r: httpx.Response) -> ApiError:
    return ApiError.from_response(
        r.status_code,
        r.headers.get("content-type", ""),
        r.read(),
        _retry_after(r),
        url=str(r.request.url),
    )


def _fraction(x: float) -> str:
    """A mesh size or time step as the fraction it was written as ("1/128", "2"): the
    nearest fraction with a denominator up to 10^6 (exact for the powers of two of a
    ladder)."""
    f = Fraction(x).limit_denominator(1_000_000)
    return str(f.numerator) if f.denominator == 1 else f"{f.numerator}/{f.denominator}"


def _umask() -> int:
    """The process's umask (read by setting it, so set it straight back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


class Client:
    """A contact-sim service at ``url``.

    ``token`` is sent as ``Authorization: Bearer <token>`` on every request. Submissions
    refused for load (429 rate limit, 503 queue full) are retried up to ``retries`` times
    after the server's Retry-After: nothing was created by a refused request, so retrying
    cannot duplicate a job. Use as a context manager, or call :meth:`close`."""

    def __init__(
        self,
        url: str = "http://127.0.0.1:8080",
        token: Optional[str] = None,
        *,
        timeout: float = 60.0,
        retries: int = 5,
    ) -> None:
        if not url.startswith(("http://", "https://")):
            raise ValueError(
                f"url {url!r}: give the service's address with its scheme, "
                "e.g. http://127.0.0.1:8080"
            )
        headers = {"User-Agent": f"contact-sim-python/{__version__}"}
        if token:
            headers["Authorization"] = f"Bearer {token}"
        self.url = url.rstrip("/")
        self.retries = retries
        self._http = httpx.Client(base_url=self.url, headers=headers, timeout=timeout)
        self._studies: Optional[List[str]] = None

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._http.close()

    def __repr__(self) -> str:
        return f"Client({self.url!r})"

    # -- transport ----------------------------------------------------------------------

    def _send(self, method: str, path: str, **kw: Any) -> httpx.Response:
        """One request; 4xx/5xx raise :class:`ApiError`, 429/503 are retried first."""
        for attempt in range(self.retries + 1):
            try:
                r = self._http.request(method, path, **kw)
            except httpx.TransportError as e:
                raise ServiceUnreachable(self.url, e) from e
            if r.status_code in (429, 503) and attempt < self.retries:
                wait = _retry_after(r)
                time.sleep(min(60.0, wait if wait is not None else 2.0**attempt))
                continue
            if r.status_code >= 400:
                raise _error(r)
            return r
        raise AssertionError("unreachable")

    def _json(self, method: str, path: str, **kw: Any) -> Any:
        return self._send(method, path, **kw).json()

    def _download(self, path: str, dest: Path) -> Path:
        """Streams a response body into ``dest`` (complete or not at all)."""
        dest.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=dest.parent, prefix=f".{dest.name}.", suffix=".part")
        try:
            try:
                with os.fdopen(fd, "wb") as out, self._http.stream("GET", path) as r:
                    if r.status_code >= 400:
                        raise _error(r)
                    for chunk in r.iter_bytes():
                        out.write(chunk)
            except httpx.TransportError as e:
                raise ServiceUnreachable(self.url, e) from e
            # mkstemp creates the file 0600; a download gets the mode any new file of this
            # user gets (0666 less the umask), as open() would have given it.
            os.chmod(tmp, 0o666 & ~_umask())
            os.replace(tmp, dest)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return dest

    def _pages(self, path: str, key: str, params: Dict[str, Any]) -> Iterator[Any]:
        """The items of a paginated listing, following ``next`` (a URL with its query: the
        cursor, limit and filter) until it is null."""
        page = self._json("GET", path, params=params)
        yield from page[key]
        while page.get("next"):
            page = self._json("GET", page["next"])
            yield from page[key]

    # -- jobs ---------------------------------------------------------------------------

    def submit(
        self,
        scene_or_preset: Submission,
        overrides: Optional[Mapping[str, Ratio]] = None,
        idempotency_key: Optional[str] = None,
    ) -> "Job":
        """Submits a preset by name (with ``overrides`` of ``h``, ``k``, ``T`` or ``t_end``;
        a study preset's name, e.g. "paper-table-1", submits that study), or a document: a scene,
        ``{"preset": ..., "overrides": ...}`` or a study ``{"study": {...}}``. A path reads
        the document from a JSON file: a ``Path`` (any ``os.PathLike``), or a string that ends
        in ``.json`` or holds a ``/`` (no preset name does); a missing file raises
        ``FileNotFoundError`` naming it.

        The same computation as one already computed (the same scene but for its name) is
        answered with that job (already succeeded). With ``idempotency_key``, the same key and body give the same job, so a
        submission can be retried safely after a lost answer."""
        body: Dict[str, Any]
        if isinstance(scene_or_preset, str) and _is_path(scene_or_preset):
            scene_or_preset = Path(scene_or_preset)
        if isinstance(scene_or_preset, str):
            if scene_or_preset in self._study_presets():
                if overrides:
                    raise ValueError("a study preset takes no overrides: its levels are fixed")
                body = {"study": {"preset": scene_or_preset}}
            else:
                body = {"preset": scene_or_preset}
        elif isinstance(scene_or_preset, os.PathLike):
            path = Path(scene_or_preset)
            try:
                text = path.read_text(encoding="utf-8")
            except FileNotFoundError:
                raise FileNotFoundError(f"no such file: {path}") from None
            body = json.loads(text)
        else:
            body = dict(scene_or_preset)
        if overrides:
            if "preset" not in body:
                raise ValueError(
                    "overrides apply to a preset; in a scene set mesh.h, time.k and "
                    "time.t_end instead"
                )
            body["overrides"] = {
                **body.get("overrides", {}),
                **{k: _ratio(v) for k, v in overrides.items()},
            }
        headers = {"Idempotency-Key": idempotency_key} if idempotency_key else {}
        return Job(self, self._json("POST", "/jobs", json=body, headers=headers))

    def target(
        self,
        scene: Union[str, Mapping[str, Any]],
        error: float,
        quantity: str = "w",
        budget_s: Optional[float] = None,
        name: Optional[str] = None,
        meshes: str = "uniform",
    ) -> "Job":
        """Submits a target study: the cheapest run of ``scene`` (a preset name or a scene
        document) whose relative error at t = T in ``quantity`` ("w", "u" or "zeta") is below
        ``error``, within ``budget_s`` seconds if given. The job's summary has the choice
        (``chosen``), the fitted models and the pilots; its fields, VTU and archive are the
        chosen run's. A target out of reach fails the job with the reason in its error.
        With ``meshes="auto"`` (quantity "w" only) the chosen run may be on an adaptive mesh
        with fewer nodes and an a posteriori estimate no larger than the uniform level's; the
        summary's ``meshes`` says which was taken and why, and ``final_mesh`` names the
        adaptive mesh stored."""
        target: Dict[str, Any] = {"error": error, "quantity": quantity}
        if meshes != "uniform":
            target["meshes"] = meshes
        study: Dict[str, Any] = {
            "scene": scene if isinstance(scene, str) else dict(scene),
            "target": target,
        }
        if budget_s is not None:
            study["budget_s"] = budget_s
        if name is not None:
            study["name"] = name
        return self.submit({"study": study})

    def adapt(
        self,
        scene: Union[str, Mapping[str, Any]],
        target: float,
        theta: float = 0.5,
        max_nodes: Optional[int] = None,
        max_cycles: Optional[int] = None,
        uniform: bool = True,
        reference_refine: Optional[int] = None,
        name: Optional[str] = None,
    ) -> "Job":
        """Submits an adaptive study: ``scene`` (a preset name or a scene document) run on
        meshes refined by bisection where its a posteriori estimate is largest (Dörfler's
        marking with share ``theta``), until the velocity's relative estimate over the run is
        at most ``target``, the next mesh would pass ``max_nodes`` or ``max_cycles`` cycles
        ran. ``uniform`` also runs the initial mesh refined uniformly up to the last cycle's
        size; ``reference_refine`` r measures every run's true error against the initial mesh
        refined uniformly to h/2^r. The job's summary has ``cycles``, ``uniform``,
        ``reference``, ``reached``, ``stopped`` and ``final_mesh`` (an uploaded mesh of
        yours); its fields, VTU and archive are the last cycle's. :meth:`Job.adapt_table`
        gives the rows as a DataFrame."""
        adapt: Dict[str, Any] = {"target": target, "theta": theta, "uniform": uniform}
        if max_nodes is not None:
            adapt["max_nodes"] = max_nodes
        if max_cycles is not None:
            adapt["max_cycles"] = max_cycles
        study: Dict[str, Any] = {
            "scene": scene if isinstance(scene, str) else dict(scene),
            "adapt": adapt,
        }
        if reference_refine is not None:
            study["reference"] = {"refine": reference_refine}
        if name is not None:
            study["name"] = name
        return self.submit({"study": study})

    def continue_(
        self,
        job: Union[str, "Job"],
        t_end: Optional[Ratio] = None,
        scene: Optional[Mapping[str, Any]] = None,
    ) -> "Job":
        """Continues a finished simulation ``job`` (a :class:`Job` or its id) from the state
        after its last step to the final time ``t_end``, with the parent's step k: the same
        steps as one run to ``t_end``, numbered from the parent's start; the new job's summary
        has ``continued_from``. ``scene`` changes loads, friction, output or solver for the
        continuation (the mesh and the body must stay the parent's; its ``time`` may only give
        ``t_end``). The same continuation twice is answered with the first job. A parent that
        has not stored its last state (unfinished, failed) is refused: :class:`ApiError` 422
        at ``/continue/job``."""
        request: Dict[str, Any] = {"job": job.id if isinstance(job, Job) else str(job)}
        if t_end is not None:
            request["t_end"] = _ratio(t_end)
        if scene is not None:
            request["scene"] = dict(scene)
        return Job(self, self._json("POST", "/jobs", json={"continue": request}))

    def sweep(
        self,
        scene: Union[str, Mapping[str, Any]],
        vary: Mapping[str, Sequence[Any]],
        mode: str = "grid",
        name: Optional[str] = None,
        progress: bool = True,
        timeout: Optional[float] = None,
    ) -> "pandas.DataFrame":
        """Runs a parameter sweep (a job whose members run as jobs of their own), waits, and
        returns its table as a DataFrame (needs the
        pandas extra): ``scene`` (a preset name or a scene document) with the values of
        ``vary`` (JSON pointers into the scene, e.g. ``{"/friction/g": [0.5, 1, 2],
        "/damage/kappa": [0.1, 0.5]}``) substituted, every combination (``mode="grid"``, the
        first pointer slowest) or the i-th values together (``"zip"``). One row per member:
        a column per pointer, ``w_V``, ``u_V``, ``zeta_L2``, ``zeta_min`` (at T),
        ``min_zeta`` (over the run), ``slip_nodes``, ``max_slip_speed`` (at T), ``steps``,
        ``wall_s``, ``cached`` (taken from an earlier job of the same scene), ``job`` (the
        member's job id). ``attrs`` has the sweep's job id (``job``) and the sweep's
        ``name``, ``mode`` and ``computed``. A bad
        pointer or value raises :class:`ApiError` 422 at ``/sweep/vary/<pointer>``."""
        sweep: Dict[str, Any] = {
            "scene": scene if isinstance(scene, str) else dict(scene),
            "vary": {k: list(v) for k, v in vary.items()},
            "mode": mode,
        }
        if name is not None:
            sweep["name"] = name
        job = self.submit({"sweep": sweep}).wait(progress=progress, timeout=timeout)
        return job.sweep_table()

    def _study_presets(self) -> List[str]:
        """Names of the server's study presets (asked once per client)."""
        if self._studies is None:
            listing = self._json("GET", "/presets")
            self._studies = [s["name"] for s in listing.get("studies", [])]
        return self._studies

    def job(self, job_id: str) -> "Job":
        """The job with this id (404 raises :class:`ApiError`)."""
        return Job(self, self._json("GET", f"/jobs/{job_id}"))

    def jobs(self, status: Optional[str] = None, page_size: int = 50) -> Iterator["Job"]:
        """Every job, newest first, fetched ``page_size`` at a time as the iteration goes;
        ``status`` keeps one of queued, running, succeeded, failed, cancelled."""
        params: Dict[str, Any] = {"limit": page_size}
        if status is not None:
            params["status"] = status
        for resource in self._pages("/jobs", "jobs", params):
            yield Job(self, resource)

    # -- meshes -------------------------------------------------------------------------

    def upload_mesh(self, path: Union[str, "os.PathLike[str]"]) -> str:
        """Uploads a gmsh ``.msh`` file (MSH 4.1, ASCII or binary) and returns its id, the
        SHA-256 of the file, for a scene's ``"domain": {"mesh": id}``. Uploading the same
        file again returns the same id."""
        data = Path(path).read_bytes()
        r = self._send(
            "POST",
            "/meshes",
            content=data,
            headers={"Content-Type": "application/octet-stream"},
        )
        return str(r.json()["id"])

    def mesh(self, mesh_id: str) -> Dict[str, Any]:
        """An uploaded mesh: ``id``, ``bytes``, ``created_at`` and its ``summary`` (nodes,
        cells, groups, bounding box, cell sizes, quality)."""
        return dict(self._json("GET", f"/meshes/{mesh_id}"))

    def meshes(self, page_size: int = 50) -> Iterator[Dict[str, Any]]:
        """Every uploaded mesh, newest first, fetched ``page_size`` at a time."""
        yield from self._pages("/meshes", "meshes", {"limit": page_size})

    def delete_mesh(self, mesh_id: str) -> None:
        """Removes an uploaded mesh (409 while a queued or running job uses it)."""
        self._send("DELETE", f"/meshes/{mesh_id}")

    # -- the rest -----------------------------------------------------------------------

    def presets(self) -> List[Dict[str, Any]]:
        """The built-in scenes: ``name``, ``description``, ``href``."""
        return list(self._json("GET", "/presets")["presets"])

    def preset(self, name: str) -> Dict[str, Any]:
        """A built-in scene as a complete scene document, to edit and submit."""
        return dict(self._json("GET", f"/presets/{name}"))

    def health(self) -> Dict[str, Any]:
        return dict(self._json("GET", "/healthz"))


class Job:
    """A submitted simulation or study. ``resource`` is the job as last fetched (status,
    progress, times, error, links); :meth:`refresh` fetches it again."""

    def __init__(self, client: Client, resource: Mapping[str, Any]) -> None:
        self.client = client
        self.resource: Dict[str, Any] = dict(resource)
        self.id: str = str(resource["id"])
        self._dim: Optional[int] = None

    def __repr__(self) -> str:
        return f"<Job {self.id} {self.kind} {self.status}>"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Job) and other.id == self.id

    def __hash__(self) -> int:
        return hash(self.id)

    @property
    def status(self) -> str:
        return str(self.resource["status"])

    @property
    def kind(self) -> str:
        """``simulation`` or ``study``."""
        return str(self.resource.get("kind", "simulation"))

    @property
    def progress(self) -> Dict[str, Any]:
        """``step``, ``steps``, ``percent``, ``eta_s``, ``last_residual``."""
        return dict(self.resource.get("progress") or {})

    @property
    def finished(self) -> bool:
        return self.status in FINISHED

    def _path(self, tail: str = "") -> str:
        return f"/jobs/{self.id}{tail}"

    def refresh(self) -> "Job":
        self.resource = dict(self.client._json("GET", self._path()))
        return self

    # -- waiting ------------------------------------------------------------------------

    def wait(
        self,
        progress: bool = True,
        timeout: Optional[float] = None,
        events: bool = True,
    ) -> "Job":
        """Blocks until the job is finished and returns it once succeeded.

        Follows the job's event stream (``GET /jobs/{id}/events``); where that is not
        available (a proxy that buffers, a cut connection) it polls ``GET /jobs/{id}``
        after each Retry-After, with ``If-None-Match``; ``events=False`` polls from the
        start. ``progress`` shows a tqdm bar (steps, ETA) when tqdm is installed.

        Raises :class:`JobFailed` (with the job's problem) or :class:`JobCancelled`, and
        ``TimeoutError`` after ``timeout`` seconds (the job keeps running)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        bar = _Progress(progress, self)
        try:
            final = self._follow_events(bar, deadline) if events else None
            if final is None:
                self._poll(bar, deadline)
            else:
                self.refresh()
                bar.show(self.progress, self.status)
        finally:
            bar.close()
        return self._check()

    def _check(self) -> "Job":
        if self.status == "failed":
            error = self.resource.get("error") or {
                "type": "about:blank",
                "title": "job failed",
                "status": 500,
                "detail": "the job failed without a recorded reason",
            }
            raise JobFailed(self.id, error)
        if self.status == "cancelled":
            raise JobCancelled(self.id)
        return self

    @staticmethod
    def _remaining(deadline: Optional[float]) -> Optional[float]:
        if deadline is None:
            return None
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError("the job did not finish in time")
        return left

    def _follow_events(self, bar: "_Progress", deadline: Optional[float]) -> Optional[str]:
        """The final status from the event stream, or None when the stream is unusable or
        ended early (the caller polls then)."""
        # The server sends a keep-alive comment every 15 s: a longer silence is a dead
        # connection.
        left = self._remaining(deadline)
        read = 45.0 if left is None else min(45.0, left)
        timeout = httpx.Timeout(10.0, read=read)
        try:
            with self.client._http.stream(
                "GET",
                self._path("/events"),
                headers={"Accept": "text/event-stream"},
                timeout=timeout,
            ) as r:
                if r.status_code == 404:
                    raise _error(r)
                ctype = r.headers.get("content-type", "")
                if r.status_code != 200 or not ctype.startswith("text/event-stream"):
                    return None
                for ev in _sse.events(r.iter_lines()):
                    try:
                        data = json.loads(ev.data)
                    except ValueError:
                        continue
                    status = str(data.get("status", ""))
                    self.resource["status"] = status
                    bar.show(data, status)
                    if ev.event == "status" or status in FINISHED:
                        return status
                    self._remaining(deadline)
        except httpx.TimeoutException:
            self._remaining(deadline)
        except httpx.TransportError:
            pass
        return None

    def _poll(self, bar: "_Progress", deadline: Optional[float]) -> None:
        etag: Optional[str] = None
        failures = 0
        while True:
            left = self._remaining(deadline)
            headers = {"If-None-Match": etag} if etag else {}
            try:
                r = self.client._http.get(self._path(), headers=headers)
            except httpx.TransportError:
                # A restarting server: bounded retries, then the error.
                failures += 1
                if failures > 5:
                    raise
                time.sleep(1.0 if left is None else min(1.0, left))
                continue
            failures = 0
            if r.status_code >= 400:
                raise _error(r)
            if r.status_code == 200:
                self.resource = dict(r.json())
                etag = r.headers.get("etag")
                bar.show(self.progress, self.status)
                if self.finished:
                    return
            pause = _retry_after(r)
            pause = 1.0 if pause is None else pause
            left = self._remaining(deadline)
            time.sleep(pause if left is None else min(pause, left))

    # -- results ------------------------------------------------------------------------

    def summary(self) -> Dict[str, Any]:
        """The run summary (norms per step, solver figures, timings), or a study's error
        table as JSON (``rows``, ``reference``, ``lsq_order_w``, ...)."""
        return dict(self.client._json("GET", self._path("/summary")))

    def table(self) -> "pandas.DataFrame":
        """A study's table as a DataFrame, one row per level: ``h``, ``k`` (floats, each
        followed by ``h_fraction``, ``k_fraction``: the same as a fraction, "1/128"; and
        ``refine`` on a given mesh), ``err_w``, ``err_zeta``, ``order_w``, ... ; nested figures are
        flattened (``velocity_iterations_mean``). ``attrs`` carries the reference run,
        ``vary`` and the least-squares orders. Needs the pandas extra."""
        import pandas as pd

        s = self.summary()
        if s.get("kind") != "study":
            raise ValueError(f"job {self.id} is a simulation; tables are made by studies")
        df = pd.json_normalize(s["rows"], sep="_")
        # h and k as the fractions the study was written in ("1/128"), beside the floats.
        for col in ("h", "k"):
            if col in df.columns:
                df.insert(
                    list(df.columns).index(col) + 1, f"{col}_fraction", df[col].map(_fraction)
                )
        for key in ("name", "vary", "reference", "lsq_order_w", "lsq_order_zeta"):
            if key in s:
                df.attrs[key] = s[key]
        return df

    def sweep_table(self) -> "pandas.DataFrame":
        """A sweep's table as a DataFrame, one row per member (see :meth:`Client.sweep`)."""
        import pandas as pd

        s = self.summary()
        if s.get("kind") != "sweep":
            raise ValueError(f"job {self.id} is not a sweep")
        pointers = [v["pointer"] for v in s["vary"]]
        records = []
        for row in s["rows"]:
            rec = {p: row["values"].get(p) for p in pointers}
            rec.update({k: v for k, v in row.items() if k not in ("values", "member")})
            records.append(rec)
        df = pd.DataFrame.from_records(records, index=[r["member"] for r in s["rows"]])
        df.index.name = "member"
        df.attrs["job"] = self.id
        for key in ("name", "mode", "computed"):
            df.attrs[key] = s.get(key)
        return df

    def adapt_table(self) -> "pandas.DataFrame":
        """An adaptive study's runs as a DataFrame, one row per run: ``run`` ("cycle", "uniform"
        or "reference"), ``index`` (the cycle, or the uniform line's halvings of h),
        ``nodes``, ``cells``, ``unknowns``, ``generation``, ``estimate`` (relative),
        ``estimate_abs``, ``time_share``, ``error`` (true, relative; NaN without a reference),
        ``marked`` and ``seconds``. ``attrs`` has ``reached``, ``stopped``, ``target`` and
        ``final_mesh``. Needs the pandas extra."""
        import pandas as pd

        s = self.summary()
        if s.get("kind") != "adapt":
            raise ValueError(f"job {self.id} is not an adaptive study")
        records = []
        for run, rows in (("cycle", s["cycles"]), ("uniform", s["uniform"])):
            for i, row in enumerate(rows):
                records.append({"run": run, "index": i, **row})
        if s.get("reference"):
            records.append({"run": "reference", "index": 0, **s["reference"]})
        df = pd.DataFrame.from_records(records)
        df.attrs["job"] = self.id
        for key in ("name", "reached", "stopped", "target", "theta", "final_mesh"):
            df.attrs[key] = s.get(key)
        return df

    def table_text(self) -> str:
        """A study's table in the layout of the paper's Tables 1–2."""
        return self.client._send("GET", self._path("/summary"), params={"format": "text"}).text

    def report_svg(self) -> str:
        """A study's report: errors against h (or k) with slope guides, and work–precision."""
        return self.client._send("GET", self._path("/report.svg")).text

    def fields(
        self,
        step: Union[int, str] = "last",
        names: Optional[Sequence[str]] = None,
        mesh: bool = True,
        surface: bool = False,
    ) -> Fields:
        """Step ``step`` (a stored step, 0 for the initial state, or "last") as numpy
        arrays: ``names`` is a subset of u, w, zeta, sigma, von_mises, contact (default
        all), ``mesh`` adds nodes, cells and the boundary. ``surface``: a 3D job's fields
        (and mesh) on its boundary surface only, a small part of a fine mesh (a 2D job's
        come whole either way). See :class:`Fields`."""
        params: Dict[str, str] = {"step": str(step)}
        if names is not None:
            params["fields"] = ",".join(names)
        if mesh:
            params["mesh"] = "1"
        if surface:
            params["surface"] = "1"
        doc = self.client._json("GET", self._path("/fields"), params=params)
        dim = None
        if not mesh and ("u" in doc or "w" in doc) and "sigma" not in doc:
            dim = self._dimension()
        return Fields.from_json(doc, dim)

    def _dimension(self) -> int:
        if self._dim is None:
            self._dim = int(self.summary()["mesh"]["dim"])
        return self._dim

    def vtu(self, step: Union[int, str] = "last", compression: str = "zlib") -> bytes:
        """Step ``step`` as a VTK UnstructuredGrid (.vtu) file's bytes, its arrays
        zlib-compressed (``compression="zlib"``, what ParaView, VTK and meshio read) or raw
        (``"none"``)."""
        return self.client._send(
            "GET", self._path(f"/fields/{step}.vtu"), params={"compression": compression}
        ).content

    def to_meshio(self, step: Union[int, str] = "last") -> "meshio.Mesh":
        """Step ``step`` as a meshio Mesh, read from the service's VTU: 3D points (z = 0 in
        2D), ``triangle`` or ``tetra`` cells, point data u, w (3 components), zeta (and the
        contact state of Γ3 nodes), cell data sigma (6 components, VTK's order xx, yy, zz,
        xy, yz, xz) and von_mises, field data TimeValue and Step. Needs the meshio extra."""
        import meshio

        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / f"step-{step}.vtu"
            path.write_bytes(self.vtu(step))
            return meshio.read(path)

    def download(
        self, path: Union[str, "os.PathLike[str]"] = ".", compression: str = "zlib"
    ) -> Path:
        """Saves the whole result as one tar archive (scene, summary, PVD, the VTU of every
        step, in one folder named after the job) and returns its path; a directory gets
        ``contact-sim-<id>.tar`` inside it (a path ending in a slash is a directory, created
        if need be). ``compression`` is the VTU files' (``"zlib"`` or ``"none"``, as in
        :meth:`vtu`)."""
        dest = Path(path)
        if dest.is_dir() or str(path).endswith(("/", os.sep)):
            dest = dest / f"contact-sim-{self.id}.tar"
        return self.client._download(
            self._path(f"/archive.tar?compression={compression}"), dest
        )

    # -- control ------------------------------------------------------------------------

    def cancel(self) -> "Job":
        """Cancels a queued or running job (a running one stops within one time step); 409
        (:class:`ApiError`) when it has already finished otherwise."""
        self.resource = dict(self.client._json("POST", self._path("/cancel")))
        return self

    def delete(self) -> None:
        """Removes a finished job and its results (409 while it is queued or running)."""
        self.client._send("DELETE", self._path())


class _Progress:
    """A tqdm bar over the job's time steps (no-op without tqdm or when disabled). Its clock
    restarts when the job starts running, so the ETA does not count the time queued."""

    def __init__(self, enabled: bool, job: Job) -> None:
        self.bar: Any = None
        self.running = False
        self.shown = ""
        if not enabled:
            return
        try:
            from tqdm.auto import tqdm
        except ImportError:
            return
        self.bar = tqdm(total=None, desc=f"{job.kind} {job.id[:8]}", unit="step", leave=True)

    def show(self, p: Mapping[str, Any], status: str) -> None:
        bar = self.bar
        if bar is None:
            return
        steps, step = p.get("steps"), int(p.get("step") or 0)
        if status == "running" and not self.running:
            self.running = True
            bar.reset(total=steps or None)
        elif steps and bar.total != steps:
            bar.total = steps
        if step > bar.n:
            bar.update(step - bar.n)
        residual = p.get("last_residual")
        post = status if residual is None else f"{status}, residual {residual:.1e}"
        # tqdm limits its own redraws; a change of status is drawn at once.
        bar.set_postfix_str(post, refresh=status != self.shown)
        self.shown = status

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
