"""Validation of the inference and of discovery on simulated data whose truth is known; it sits above
:mod:`peano_bayes.inference` and :mod:`peano_bayes.discovery`, which never import it.

- :mod:`.sbc`: simulation-based calibration of the whole inference chain (prior draw, virtual rig, inference,
  rank and coverage of the truth).
- :mod:`.discovery_benchmark`: virtual-rig data with a hidden effect, and whether discovery names it.
"""
