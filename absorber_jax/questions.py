"""Questions a study asks of each design ([`absorber_jax.study`][absorber_jax.study]), as
objects carrying their options; subclass ``AbstractQuestion`` to ask your own.

```python
import numpy as np, absorber_jax as aj
aj.questions.FrequencyResponse(np.linspace(20, 45, 64), amplitude=3.0)
aj.questions.ExactPeak((80.0, 120.0), amplitude=1.0)
aj.questions.RobustPeak((20.0, 45.0), amplitude=3.0)
aj.questions.Attractors([30.0, 35.0], amplitude=3.0, samples=16)
```
"""

from ._study.questions import (
    AbstractQuestion,
    Attractors,
    ExactPeak,
    FrequencyResponse,
    RobustPeak,
)

__all__ = ["AbstractQuestion", "Attractors", "ExactPeak", "FrequencyResponse", "RobustPeak"]
