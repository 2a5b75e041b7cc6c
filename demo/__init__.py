"""The demos on the embedded samples (``mirrorcap demo``, ``mirrorcap demo-mirrors``) and
their HTML report. They score against the samples' truth, so they use :mod:`..synthetic`;
like it, they are left out of the extension zip."""
