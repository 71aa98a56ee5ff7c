"""The block-streaming contract: blocks, chunks, events, the pipeline and the run loop, and
sources (a recording replay; the simulator and live links are sources too).
"""

from millsense.streaming.block import Block, BlockOutput, Chunk, Event, EventKind, Severity
from millsense.streaming.engine import Pipeline, RunResult, run
from millsense.streaming.event_log import read_event_log, write_event_log
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
    "Severity",
    "Source",
    "read_event_log",
    "run",
    "write_event_log",
]
