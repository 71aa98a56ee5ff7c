"""The block-streaming engine: blocks, pipeline, sources, and the run loop."""

from millsense.online.block import Block, BlockOutput, Chunk, Event, EventKind
from millsense.online.engine import Pipeline, RunResult, run
from millsense.online.sources import RecordingSource, Source

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
