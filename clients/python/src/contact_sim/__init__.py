"""Python client of the contact-sim service: submit scenes, presets and convergence studies,
follow their progress, and read results as numpy arrays, meshio meshes or pandas tables.

    from contact_sim import Client
    client = Client("http://127.0.0.1:8080")
    job = client.submit("paper-exp3", overrides={"h": "1/16", "k": "1/16"}).wait()
    f = job.fields()            # f.nodes, f.triangles, f.u, f.zeta, f.sigma, ...
    job.download("results/")    # the archive: scene, summary, PVD and every VTU
"""

from .client import Client, Job, __version__
from .errors import ApiError, ContactSimError, JobCancelled, JobFailed, ServiceUnreachable
from .fields import Contact, Fields

__all__ = [
    "ApiError",
    "Client",
    "Contact",
    "ContactSimError",
    "Fields",
    "Job",
    "JobCancelled",
    "JobFailed",
    "ServiceUnreachable",
    "__version__",
]
