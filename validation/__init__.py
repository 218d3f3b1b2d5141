"""Physics checks of physrelight against Mitsuba 3 path tracing (``physrelight validate``).

One module per check (:mod:`validation.renderer_irradiance`, :mod:`validation.sh_model`,
:mod:`validation.shadow_loss`, :mod:`validation.lighting_solve`,
:mod:`validation.relight_ceiling`, :mod:`validation.speed`), shared tiny scenes and the
rendered scene bank in :mod:`validation.scenes`, pinned regression figures in
:mod:`validation.regression`, the list of checks in :mod:`validation.checks`, the report in
:mod:`validation.report` and the command line in :mod:`validation.cli`. Modules that render
import Mitsuba (through :mod:`synth.backend`); :mod:`validation.common`,
:mod:`validation.checks` and :mod:`validation.cli` do not.
"""
