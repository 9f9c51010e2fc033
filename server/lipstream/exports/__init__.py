"""Frame exports in the formats animators import, chosen by name or file extension.

Sketch: a ``SynthesisResult`` (frames, channels, fps) becomes the text of one
format: ``csv`` (the corpus frame CSV: ``time`` and one column per channel),
``json`` (``{"fps", "channels", "frames", "stats"}``), ``livelink`` (Live
Link Face CSV, for Unreal), or, from Preston Blair shape weights (output
visemes ``preston-blair``), Rhubarb Lip Sync's ``rhubarb-tsv``,
``rhubarb-xml``, ``rhubarb-json`` and Moho's ``moho`` switch data. The
extension picks the format when none is named: ``.csv``, ``.json``, ``.tsv``,
``.xml``, ``.dat``. ``formats`` names them (light, for the command line's
options); ``writer`` writes one, one module per format (``livelink``,
``rhubarb``, ``moho``, with ``cues`` turning shape weights into mouth cues).
"""

from .formats import EXTENSIONS, FORMATS, MOHO_FPS, SHAPE_FORMATS, format_for

__all__ = ["EXTENSIONS", "FORMATS", "MOHO_FPS", "SHAPE_FORMATS", "format_for"]
