"""Fuzzing of every registered reader (:mod:`.test_readers`), its seeds (:mod:`.seeds`),
mutations (:mod:`.mutations`) and the child processes that contain each case
(:mod:`.worker`); the hostile inputs the regression tests and docs share (:mod:`.cases`)."""
