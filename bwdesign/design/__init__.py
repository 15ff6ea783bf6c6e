"""Design: everything that chooses gains (the layer above simulation).

- :mod:`.gains`: observer gains certified for an input-rate envelope
  (:func:`synthesize`, LMI synthesis per tier with the pole-pattern search);
- :mod:`.tiers`: the ``theorem1`` and ``lipschitz`` tiers' synthesis LMIs
  (``synthesize(..., tier=...)``);
- :mod:`.tuning`: the digital tuning (:func:`digital_tuning`): observer and law
  poles for the sample rate, checked against margin requirements;
- :mod:`.robust`: the tracking loop designed against an uncertainty box
  (:func:`synthesize_robust`: candidates from the tuning, each simulated at the
  box's corners and certified by :func:`bwdesign.certify_robust`);
- :mod:`.robust_observer`: observer gains minimising the robust observer
  certificate's bound over a box (:func:`synthesize_robust_observer`);
- :mod:`.rate`: the envelope at which the robust loop certificate proves its own
  input rate (:func:`prove_rate`).

Certificates live in :mod:`bwdesign.certify` and simulation in :mod:`bwdesign.sim`;
design imports both and neither imports design.
"""

from .gains import default_pole_radius, synthesize
from .rate import RateProof, prove_rate
from .robust import (
    ENVELOPE_MARGIN,
    RobustDesign,
    RobustSearch,
    certified_envelope,
    second_envelope,
    synthesize_robust,
)
from .robust_observer import RobustObserverSynthesis, synthesize_robust_observer
from .tiers import recertify_sampled, synthesize_tier
from .tuning import (
    DigitalTuning,
    MarginRequirements,
    digital_tuning,
    observer_gains,
    stage_tuning,
)

__all__ = [
    "synthesize",
    "default_pole_radius",
    "synthesize_tier",
    "recertify_sampled",
    "digital_tuning",
    "stage_tuning",
    "DigitalTuning",
    "MarginRequirements",
    "observer_gains",
    "synthesize_robust",
    "prove_rate",
    "RateProof",
    "RobustDesign",
    "RobustSearch",
    "certified_envelope",
    "second_envelope",
    "ENVELOPE_MARGIN",
    "synthesize_robust_observer",
    "RobustObserverSynthesis",
]
