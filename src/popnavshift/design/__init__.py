"""The design of a study, read and planned without the simulator: the study model and its
YAML reader (:mod:`.study`, :mod:`.study_yaml`), the persona source and respondent specs
(:mod:`.specs`) and the plan of its runs (:mod:`.plan`). The engine runs it, the read side
(:mod:`popnavshift.read`) selects a finished folder's runs with it."""
