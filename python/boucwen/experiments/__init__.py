"""Experiments that run the library end to end on the simulated bench.

- :mod:`boucwen.experiments.reproduce`: the paper's experiment (section 4): the
  traditional offline fit on 1 Hz data against the online identifiers over
  1 → 10 → 100 → 200 Hz, Tables 1–2 and Figs. 6–9.
- :mod:`boucwen.experiments.undeclared`: records with one undeclared effect each
  (or none), diagnosed blind; with ``--online``, also identified online
  (:mod:`boucwen.experiments.undeclared_online`).
- :mod:`boucwen.experiments.plant_family`: a seeded family of benches around the
  default one; every online method's period-ahead error against the traditional model
  and the refit oracle, per frequency.
- :mod:`boucwen.experiments.long_run`: 10⁶-sample runs (the schedule repeated, random
  input, noise 0–5 nm): estimates in the well-posed region, period-ahead error against
  the traditional model, share of the integrator's implicit path.
"""
