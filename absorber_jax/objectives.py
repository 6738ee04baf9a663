"""Design objectives for [`absorber_jax.tune`][absorber_jax.tune], as objects carrying their
options.

```python
import absorber_jax as aj
aj.objectives.ExactPeak(n_freq=32, peaks=2)       # the default: exact peaks, minimax
aj.objectives.RobustPeak(probes=8)                # worst stable coexisting response too
aj.objectives.SmoothPeak(n_freq=64, softness=2e-3)
aj.objectives.MeanSquare(n_freq=64)
```
"""

from ._design.objectives import (
    AbstractObjective,
    ExactPeak,
    MeanSquare,
    RobustPeak,
    SmoothPeak,
)

__all__ = ["AbstractObjective", "ExactPeak", "MeanSquare", "RobustPeak", "SmoothPeak"]
