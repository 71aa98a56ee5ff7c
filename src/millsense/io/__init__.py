"""millsense.io: recording files (crash-safe HDF5), plan files."""

from millsense.io.recording_file import (
    RecordingStatus,
    RecordingWriter,
    read_recording,
    recording_status,
    write_recording,
)

__all__ = [
    "RecordingStatus",
    "RecordingWriter",
    "read_recording",
    "recording_status",
    "write_recording",
]
