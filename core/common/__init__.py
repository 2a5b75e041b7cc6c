"""What every stage uses: the errors the core raises (:mod:`.errors`), atomic file output
(:mod:`.files`) and the message log with progress (:mod:`.log`) that the command line
prints and the add-on's operators replay with ``self.report``. In: nothing; out: helpers."""
