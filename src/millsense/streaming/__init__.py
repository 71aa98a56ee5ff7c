"""The block-streaming contract: blocks, chunks, events, the pipeline and the run loop, and
sources (a recording replay; the simulator and live links are sources too).
"""

from millsense.streaming.block import Block, BlockOutput, Chunk, Event, EventKind
from millsense.streaming.engine import Pipeline, RunResult, run
from millsense.streaming.sources import RecordingSource, Source

__all__ = [
    "Block",
    "BlockOutput",
    "Chunk",
    "Event",
    "EventKind",
    "Pipeline",
    "RecordingSource",
    "RunResult",
    "Source",
    "run",
]
