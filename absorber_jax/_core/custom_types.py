"""jaxtyping aliases used across the package (one place, as in diffrax)."""

from typing import Union

import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int  # noqa: F401

Scalar = Float[Array, ""]
ScalarLike = Union[float, int, np.floating, ArrayLike]
State = Float[Array, " n"]
States = Float[Array, "t n"]
Times = Float[Array, " t"]
Status = Int[Array, "..."]
Flag = Bool[Array, "..."]

__all__ = ["Scalar", "ScalarLike", "State", "States", "Times", "Status", "Flag"]
