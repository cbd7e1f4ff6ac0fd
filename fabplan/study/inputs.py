"""What every task of a study on a Dask cluster reads: the study and the design."""

from __future__ import annotations

import uuid
from typing import Any

__all__ = ["shared_inputs"]


def _value(value: Any) -> Any:
    return value


def shared_inputs(client: Any, *values: Any) -> list[Any]:
    """Futures of values every task reads (the study, the design): tasks of their own, not
    scattered data, so that the scheduler can compute them again on another worker when
    the workers holding them are lost (scattered data is lost with them, and a worker that
    joins late has none)."""
    return [client.submit(_value, v, key=f"input-{k}-{uuid.uuid4().hex}", pure=False)
            for k, v in enumerate(values)]
