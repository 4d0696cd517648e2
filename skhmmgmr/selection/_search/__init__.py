"""The search over recordings, shared by every selector and the framework.

``base`` (``RecordingSearchMixin``: the selectors' shared parameters and their one door to
evaluation; ``RecordingSelector``, the base of the feature selectors), ``_evaluation`` (the
full search: every model fitted on the training recordings of every split and scored per
validation recording, in parallel, cached and shared between search steps) and
``_score_tables`` (tables of compared models). Another search strategy (one that fits fewer
or cheaper models) is a module of its own here, beside ``_evaluation``, chosen at that door.
Private: nothing here imports the selectors or the framework.
"""
