"""A Python client of the optimis job server (``optimis serve``).

Submit simulation jobs, wait for them, and read their noise and weights tables as pandas
DataFrames::

    from optimis_client import Client

    client = Client("http://127.0.0.1:8080")          # token: $OPTIMIS_TOKEN
    job = client.submit({"preset": "paper-table1", "iterations": 10000, "seed": 1})
    client.wait(job["id"])
    print(client.noise_table(job["id"]))

Weights artifacts (``optimis weights``, ``client.weights_artifact(id)``) evaluate without a
server, in numpy::

    from optimis_client import WeightFunction, model_path

    f = WeightFunction.load("weights.json")           # or client.weight_function(id)
    w1 = f.weight_of(1, model_path(f, x2, x3))

Errors: every exception is an :class:`OptimisError` — :class:`ApiError` (the server's problem
document), :class:`ServerUnreachable` (:class:`RequestTimeout`, a :class:`TimeoutError`, when a
request took longer than the client's ``timeout``), :class:`ResponseTooLarge` (an answer over
``max_response_bytes``), :class:`UnexpectedRedirect` (redirects are never followed),
:class:`JobFailed` (:class:`SweepFailed`) and :class:`WaitTimeout` (a :class:`TimeoutError`).
"""

from ._client import (
    DEFAULT_MAX_RESPONSE_BYTES,
    DEFAULT_URL,
    FINAL_STATES,
    MAX_WAIT_SECONDS,
    Client,
    effective_weights_frame,
)
from ._errors import (
    ApiError,
    JobFailed,
    OptimisError,
    RequestTimeout,
    ResponseTooLarge,
    ServerUnreachable,
    SweepFailed,
    UnexpectedRedirect,
    WaitTimeout,
)
from ._frames import (
    compare_frame,
    error_plan_frame,
    history_frame,
    noise_table_frame,
    paper_figures,
    radii_frame,
    sweep_table_frame,
    weights_frame,
)
from .weights import (
    CellAxes,
    Heuristic,
    ModelPath,
    Ring,
    Scene,
    WeightFunction,
    WeightVectors,
    cell_index,
    check_vectors,
    lobe_pdf,
    model_path,
    read_vectors,
    start_density,
    vector_errors,
)

__version__ = "0.1.0"

__all__ = [
    "DEFAULT_MAX_RESPONSE_BYTES",
    "DEFAULT_URL",
    "FINAL_STATES",
    "MAX_WAIT_SECONDS",
    "ApiError",
    "CellAxes",
    "Client",
    "Heuristic",
    "JobFailed",
    "ModelPath",
    "OptimisError",
    "RequestTimeout",
    "ResponseTooLarge",
    "Ring",
    "Scene",
    "ServerUnreachable",
    "SweepFailed",
    "UnexpectedRedirect",
    "WaitTimeout",
    "WeightFunction",
    "WeightVectors",
    "cell_index",
    "check_vectors",
    "compare_frame",
    "effective_weights_frame",
    "error_plan_frame",
    "history_frame",
    "lobe_pdf",
    "model_path",
    "noise_table_frame",
    "paper_figures",
    "radii_frame",
    "read_vectors",
    "start_density",
    "sweep_table_frame",
    "vector_errors",
    "weights_frame",
    "__version__",
]
