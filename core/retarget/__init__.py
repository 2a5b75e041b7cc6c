"""Retargeting a take to other faces: ARKit-52 blendshape weights (:mod:`.arkit`) and the
Live Link Face CSV the iPhone app writes (:mod:`.livelink`)."""
