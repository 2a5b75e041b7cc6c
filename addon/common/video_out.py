"""Render output as an H.264 MP4 through Blender's FFmpeg (the demo's preview, the sample clip)."""

from __future__ import annotations


def h264_output(render, path, quality: str = "MEDIUM", gop_size: int | None = None) -> None:
    """Point ``scene.render`` at ``path`` as H.264 in MP4 at the constant-rate ``quality``
    (``'PERC_LOSSLESS'``, ``'HIGH'``, ``'MEDIUM'``, ...)."""
    if hasattr(render.image_settings, "media_type"):      # Blender 5.0: stills and videos split
        render.image_settings.media_type = "VIDEO"
    render.image_settings.file_format = "FFMPEG"
    render.ffmpeg.format = "MPEG4"
    render.ffmpeg.codec = "H264"
    render.ffmpeg.constant_rate_factor = quality
    if gop_size is not None:
        render.ffmpeg.gopsize = gop_size
    render.use_file_extension = False
    render.filepath = str(path)
