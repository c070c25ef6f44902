"""The outcome a command-line run reports on stderr: its last line, the warnings before it prefixed ``warning:``."""

__all__ = ["outcome_lines", "run_files"]


def outcome_lines(err: str) -> list[str]:
    """The lines of ``err`` that are not warnings (a failure: exactly one)."""
    return [line for line in err.strip().splitlines() if line and not line.startswith("warning: ")]


def run_files(directory) -> dict[str, bytes]:
    """Every file below ``directory`` (relative path -> contents): a run's outputs, subfolders included."""
    return {str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()}
