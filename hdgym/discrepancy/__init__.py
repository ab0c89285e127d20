"""Discrepancy workflow: compare a model with measured data, name the missing effects.

Modules, one job each:

* :mod:`.registry` -- the effect registry shared with the simulator switches, built from
  :mod:`.gear_effects` and :mod:`.friction_effects` (:mod:`.effect`: what an effect is;
  :mod:`.paths`: dotted parameter paths);
* :mod:`.residuals` -- comparison channels, filter, NMSE, signatures, localization;
* :mod:`.problem` -- a record prepared for comparison (multiple shooting in :mod:`.restarts`,
  the inverse-dynamics comparison in :mod:`.inverse`, sizes read from it in
  :mod:`.record_scales`);
* :mod:`.fitting` -- bounded least-squares fits of dotted parameters;
* :mod:`.diagnosis` -- the outcome of a diagnosis (data only); :mod:`.outcome` -- named,
  nothing missing or unexplained, and the next experiment;
* :mod:`.workflow` -- fit, localize, name, add, refit, repeat;
* :mod:`.report` -- report.json + report.md + figures, written atomically;
* :mod:`.command` -- ``hdgym diagnose``: read records, diagnose, write the report;
* :mod:`.experiments` -- identification protocols as command signals (``hdgym experiment``);
* :mod:`.bench` -- timing of a diagnosis;
* :mod:`.cases` -- hidden-effect cases (``python -m hdgym.discrepancy.cases``);
* :mod:`.zxf17` -- the shipped ZXF17 real data (data/zxf17) read as records;
* :mod:`.realdata` -- the workflow on real sweeps: per-file and cross-record tables;
* :mod:`.holdout` -- blind and hold-out cases, never used for tuning.
"""
