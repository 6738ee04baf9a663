"""absorber_jax: differentiable simulation, sweeps and design of impact and friction
vibration absorbers.

The two systems and seven laws are those of C. Mrad, K. Chehaibi, A. Nasr, R. Nasri,
"Modeling effect on the performance of impact and friction vibration absorbers",
*Mechanics & Industry* 18, 206 (2017), doi:10.1051/meca/2016040: an impact absorber
(``ImpactAbsorber``: a mass in a clearance, with the Kelvin–Voigt, Hertz or Hunt–Crossley
contact law) and a friction absorber (``FrictionAbsorber``: a mass tied by a spring and
dashpot and sliding under a normal force, with the Coulomb, Stribeck, Dahl or LuGre friction
law).  ``StructuralSystem`` attaches any number of such absorbers, tuned mass dampers and
contacts to a multi-degree-of-freedom ``LinearStructure``.  The Mechanics page of the
documentation gives the equations, units, the paper's tables and its corrections.

Importing the package enables JAX's float64 mode (``jax_enable_x64``): the default path of
every computation here is double precision.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from ._core.cache import setup_on_import as _setup_cache  # noqa: E402

_setup_cache()  # the persistent compilation cache (absorber_jax._core.cache)

from . import objectives, presets, questions  # noqa: E402
from ._continuation.branch import Bifurcation, Branch  # noqa: E402
from ._continuation.continuation import band_continuation, continuation  # noqa: E402
from ._continuation.method import PseudoArclength  # noqa: E402
from ._core.devices import use_cpu_cores  # noqa: E402
from ._core.status import Status, describe  # noqa: E402
from ._design.base import band_objective, smooth_max  # noqa: E402
from ._design.peak import BandPeak, exact_peak  # noqa: E402
from ._design.robust import Coexisting, RobustPeak, robust_peak  # noqa: E402
from ._design.tune import plot_tuning, tune, value_and_grad  # noqa: E402
from ._integration.settings import Integrator  # noqa: E402
from ._integration.simulate import REGIME_NAMES, SOLVERS, Trajectory, choose_solver, simulate  # noqa: E402
from ._io.matrices import read_matrix  # noqa: E402
from ._io.plots import plot_bifurcation_diagram, plot_branches, plot_frequency_response  # noqa: E402
from ._laws.contact import (  # noqa: E402
    AbstractCompliantLaw,
    AbstractContactLaw,
    Hertz,
    HuntCrossley,
    KelvinVoigt,
)
from ._laws.friction import (  # noqa: E402
    AbstractFrictionLaw,
    AbstractMemorylessFrictionLaw,
    AbstractStickSlipLaw,
    Coulomb,
    Dahl,
    LuGre,
    Stribeck,
)
from ._laws.helpers import (  # noqa: E402
    effective_mass,
    equivalent_hertz_stiffness,
    hertz_contact_time,
    hertz_stiffness,
    hunt_crossley_damping,
    linear_contact_time,
    linear_restitution,
)
from ._laws.restitution import Restitution, restitution_of  # noqa: E402
from ._periodic.attractors import Attractor, AttractorMap, attractors, bifurcation_diagram  # noqa: E402
from ._periodic.base import (  # noqa: E402
    AbstractChainingMethod,
    AbstractSinglePassMethod,
    AbstractSteadyMethod,
)
from ._periodic.harmonic import HarmonicBalance  # noqa: E402
from ._periodic.marching import Marching  # noqa: E402
from ._periodic.modes import NonlinearModes, nonlinear_modes  # noqa: E402
from ._periodic.orbit import orbit_map, orbit_result  # noqa: E402
from ._periodic.shooting import Shooting  # noqa: E402
from ._periodic.steady import SteadyState, solve_point, steady_state  # noqa: E402
from ._periodic.sweep import FrequencyResponse, frequency_response  # noqa: E402
from ._study.designs import (  # noqa: E402
    AbstractDesigns,
    Designs,
    Grid,
    LatinHypercube,
    MonteCarlo,
)
from ._study.distributions import AbstractDistribution, Normal, Uniform  # noqa: E402
from ._study.result import StudyResult  # noqa: E402
from ._study.study import study  # noqa: E402
from ._systems.absorbers import AbstractAbsorberSystem, FrictionAbsorber, ImpactAbsorber  # noqa: E402
from ._systems.base import AbstractHybridSystem, AbstractSystem  # noqa: E402
from ._systems.elements import (  # noqa: E402
    AbstractAbsorber,
    AbstractElement,
    AbstractForceElement,
    AbstractLinearElement,
    AbstractMasslessElement,
    AbstractSpring,
    AbstractSpringAbsorber,
    Contact,
    FrictionContact,
    FrictionDamper,
    ImpactDamper,
    TunedMassDamper,
)
from ._systems.forcing import (  # noqa: E402
    AbstractForcing,
    AbstractPeriodicForcing,
    AbstractSampledPeriodicForcing,
    Harmonic,
    MultiHarmonic,
    PeriodicForcing,
    RampedHarmonic,
)
from ._systems.linear import linear_guess  # noqa: E402
from ._systems.params import get_param, parameter_names, replace_params  # noqa: E402
from ._systems.reduction import craig_bampton  # noqa: E402
from ._systems.structural import BaseExcitation, StructuralSystem  # noqa: E402
from ._systems.structure import (  # noqa: E402
    LinearStructure,
    beam_matrices,
    cantilever_beam,
    shear_building,
    structure_from_matrices,
    structure_from_modes,
)

__version__ = "0.1.0"

__all__ = [
    "Integrator",
    "AbstractAbsorberSystem", "AbstractContactLaw", "AbstractForcing", "AbstractFrictionLaw",
    "AbstractMemorylessFrictionLaw", "AbstractStickSlipLaw",
    "Coulomb", "Dahl", "FrictionAbsorber", "Harmonic", "Hertz", "HuntCrossley",
    "ImpactAbsorber", "KelvinVoigt", "LuGre", "REGIME_NAMES", "RampedHarmonic", "SOLVERS",
    "FrequencyResponse", "SteadyState", "frequency_response", "Shooting", "Marching",
    "HarmonicBalance", "NonlinearModes", "nonlinear_modes",
    "AbstractSteadyMethod", "AbstractSinglePassMethod", "AbstractChainingMethod",
    "solve_point", "orbit_map", "orbit_result", "get_param", "linear_guess",
    "parameter_names", "replace_params", "steady_state", "tune", "value_and_grad",
    "band_objective", "smooth_max", "plot_tuning", "BandPeak", "exact_peak",
    "Coexisting", "RobustPeak", "robust_peak",
    "LinearStructure", "beam_matrices", "cantilever_beam", "craig_bampton", "read_matrix",
    "shear_building", "structure_from_matrices",
    "structure_from_modes", "AbstractSystem", "AbstractHybridSystem", "StructuralSystem",
    "AbstractElement", "AbstractMasslessElement", "AbstractForceElement", "AbstractSpring",
    "AbstractLinearElement",
    "Contact",
    "FrictionContact", "FrictionDamper", "ImpactDamper", "TunedMassDamper",
    "Attractor", "AttractorMap", "attractors", "bifurcation_diagram", "plot_bifurcation_diagram",
    "Bifurcation", "Branch", "PseudoArclength", "band_continuation", "continuation",
    "plot_branches",
    "plot_frequency_response",
    "Status", "Stribeck", "Trajectory", "choose_solver", "describe", "effective_mass",
    "equivalent_hertz_stiffness", "hertz_contact_time", "hertz_stiffness",
    "hunt_crossley_damping", "linear_contact_time", "linear_restitution", "objectives",
    "presets", "simulate",
    "use_cpu_cores",
    "AbstractPeriodicForcing", "AbstractSampledPeriodicForcing", "MultiHarmonic",
    "PeriodicForcing", "BaseExcitation",
    "AbstractAbsorber", "AbstractSpringAbsorber", "AbstractCompliantLaw", "Restitution",
    "restitution_of",
    "study", "StudyResult", "questions", "AbstractDesigns", "Grid", "Designs", "MonteCarlo",
    "LatinHypercube", "AbstractDistribution", "Uniform", "Normal",
]
