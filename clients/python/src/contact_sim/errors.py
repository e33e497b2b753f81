"""Exceptions: every refusal of the service is an RFC 9457 problem+json document, kept whole
on the exception so that a script can act on its fields (status, type, pointers)."""

from __future__ import annotations

import json
from typing import Any, List, Mapping, Optional, Tuple


class ContactSimError(Exception):
    """Base class of the errors this package raises."""


class ServiceUnreachable(ContactSimError, ConnectionError):
    """No answer from the service's URL (refused, timed out, unknown host, not HTTP): the
    message names the URL; the transport error is its ``__cause__``."""

    def __init__(self, url: str, reason: BaseException) -> None:
        self.url = url
        super().__init__(
            f"cannot reach the contact-sim service at {url}: {reason or type(reason).__name__}"
        )


class ApiError(ContactSimError):
    """A 4xx/5xx answer of the service.

    ``errors`` lists the (JSON pointer, message) pairs of a 422: each pointer is an
    RFC 6901 pointer into the submitted body (``/overrides/h``, ``/material/E``)."""

    status: int
    type: str
    title: str
    detail: str
    errors: List[Tuple[str, str]]
    problem: Mapping[str, Any]
    retry_after: Optional[float]

    def __init__(
        self,
        status: int,
        problem: Mapping[str, Any],
        retry_after: Optional[float] = None,
    ) -> None:
        self.status = int(problem.get("status", status))
        self.type = str(problem.get("type", "about:blank"))
        self.title = str(problem.get("title", ""))
        self.detail = str(problem.get("detail", ""))
        self.errors = [
            (str(e.get("pointer", "")), str(e.get("message", "")))
            for e in problem.get("errors") or []
            if isinstance(e, Mapping)
        ]
        self.problem = problem
        self.retry_after = retry_after
        super().__init__(self._render())

    def _render(self) -> str:
        head = f"{self.status} {self.title}".rstrip()
        if self.detail:
            head += f": {self.detail}"
        if self.type not in ("", "about:blank"):
            head += f" [{self.type}]"
        lines = [head]
        width = max((len(p) for p, _ in self.errors), default=0)
        lines += [f"  {p or '(body)':<{width}}  {m}" for p, m in self.errors]
        return "\n".join(lines)

    @classmethod
    def from_response(cls, status: int, content_type: str, body: bytes,
                      retry_after: Optional[float] = None,
                      url: Optional[str] = None) -> "ApiError":
        """The error of a response; a body that is not problem+json (a proxy's HTML page,
        another server at a wrong URL) becomes the detail, shortened, with the URL that
        answered it."""
        problem: Any = None
        if "json" in content_type:
            try:
                problem = json.loads(body)
            except ValueError:
                problem = None
        if not isinstance(problem, Mapping):
            text = body.decode("utf-8", "replace").strip()
            problem = {
                "type": "about:blank",
                "title": "HTTP error",
                "status": status,
                "detail": (text[:500] or f"HTTP {status} with an empty body")
                + (f" (from {url}: is this the contact-sim service?)" if url else ""),
            }
        return cls(status, problem, retry_after)


class JobFailed(ApiError):
    """A job ended as ``failed``; the problem is the job's ``error`` (e.g. the smallness
    condition refused at run time)."""

    def __init__(self, job_id: str, problem: Mapping[str, Any]) -> None:
        self.job_id = job_id
        super().__init__(int(problem.get("status", 500)), problem)

    def _render(self) -> str:
        return f"job {self.job_id} failed: " + super()._render()


class JobCancelled(ContactSimError):
    """A job ended as ``cancelled`` while it was being waited for."""

    def __init__(self, job_id: str) -> None:
        self.job_id = job_id
        super().__init__(f"job {job_id} was cancelled")
