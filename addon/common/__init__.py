"""What every feature of the add-on shares: the operator base classes (:mod:`.jobs`), the
one core <-> Blender axis conversion (:mod:`.frames`), the settings and preferences
(:mod:`.properties`), head objects and .blend files (:mod:`.headio`), takes as empties
(:mod:`.take_io`), clip tracks (:mod:`.clip`) and video output (:mod:`.video_out`)."""
