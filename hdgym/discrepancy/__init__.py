"""Discrepancy workflow: compare a model with measured data, name the missing effects.

Modules, one job each:

* :mod:`.registry` -- the effect registry shared with the simulator switches;
* :mod:`.residuals` -- comparison channels, filter, NMSE, signatures, localization;
* :mod:`.fitting` -- bounded least-squares fits by simulation (or inverse dynamics);
* :mod:`.workflow` -- fit, localize, name, add, refit, repeat (``hdgym diagnose``);
* :mod:`.report` -- report.json + report.md + figures, written atomically;
* :mod:`.experiments` -- identification protocols as command signals (``hdgym experiment``);
* :mod:`.bench` -- timing of a diagnosis;
* :mod:`.cases` -- hidden-effect cases (``python -m hdgym.discrepancy.cases``);
* :mod:`.realdata` -- the ZXF17 real-data loader and run.
"""
