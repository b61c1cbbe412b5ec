"""Step control: the driver that steps a solver (:mod:`.driver`) and what it
reports of a run (:mod:`.outcome`), the step's
figures on the device (:mod:`.status`), the stable step (:mod:`.timestep`),
blow-up detection (:mod:`.detection`), the device-side policy (:mod:`.policy`)
and configuration-update criterion (:mod:`.criterion`), and the list of a
step's stages (:mod:`.plan`)."""
