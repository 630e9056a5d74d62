"""The paper's reproduction as data: its steps (each the commands behind some of the paper's claims, C1-C17),
declared in :mod:`.partial_observability`, :mod:`.locomotion`, :mod:`.appendix`, :mod:`.pendulum` and :mod:`.rlzoo`
with the vocabulary of :mod:`.actions`, listed in order by :mod:`.catalog`, run by :mod:`.execute` (``ermrl
reproduce``), the test phases' files kept in the repository by :mod:`.folders`."""
