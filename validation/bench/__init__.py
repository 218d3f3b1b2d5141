"""The relighting benchmark (``physrelight bench``): protocols, methods, strata, report.

Modules: :mod:`.data` (the views: a synth folder or rendered recipes), :mod:`.protocols`
(cross-relighting and time-lapse pairs, source variants), :mod:`.methods` (one callable per
method), :mod:`.strata` (failure-mode subsets), :mod:`.run` (levels, evaluation, timing),
:mod:`.report` (bench.md / bench.json / charts), :mod:`.cli`. See docs/bench.md.
"""
