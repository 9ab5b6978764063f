"""The campaign's folder while it runs: the resumable sample store, the settings file, the lock.

``DIR/samples.jsonl`` holds one JSON record per finished sample (:class:`SampleStore`),
``DIR/campaign_settings.json`` the settings of the campaign that owns the folder
(:func:`check_settings`), and a lock on the sample file keeps a second campaign out of the
folder (:func:`campaign_lock`). This persistence is the library's: resuming a killed campaign
needs it while the campaign runs.
"""

from __future__ import annotations

import fcntl
import json
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Mapping

from ilcdob.atomic import write_json_atomic
from ilcdob.inputs import MAX_LOG_BYTES, check_input, read_bytes, read_json

from .options import CampaignError

__all__ = ["SAMPLES_FILE", "SETTINGS_FILE", "STORE_FILES", "SampleStore", "campaign_lock", "check_settings"]

#: The sample store of a campaign folder.
SAMPLES_FILE = "samples.jsonl"
#: The settings file of a campaign folder.
SETTINGS_FILE = "campaign_settings.json"
#: The files of a campaign's store: kept when its output folder is rewritten.
STORE_FILES = (SETTINGS_FILE, SAMPLES_FILE)


class SampleStore:
    """``DIR/samples.jsonl``: one JSON record per finished sample, appended and fsynced.

    Parameters
    ----------
    path : path
        The JSONL file.
    settings_id : str
        Every record must carry this ``settings`` id (records of another campaign are refused).
    """

    def __init__(self, path: str | Path, settings_id: str) -> None:
        self.path = Path(path)
        self.settings_id = settings_id

    def load(self) -> dict[int, dict[str, Any]]:
        """Finished samples by index; a final line torn by a kill is cut off the file.

        Raises
        ------
        CampaignError
            A complete line that is not a record of this campaign, or two different records of
            one sample.
        """
        if not os.path.lexists(self.path):
            return {}
        raw = read_bytes(self.path, "campaign sample store", limit=MAX_LOG_BYTES, error=CampaignError)
        end = raw.rfind(b"\n") + 1
        if end < len(raw):  # torn last line (killed mid-write): drop it, the sample is flown again
            with open(self.path, "r+b") as f:
                f.truncate(end)
                f.flush()
                os.fsync(f.fileno())
        records: dict[int, dict[str, Any]] = {}
        for no, line in enumerate(raw[:end].splitlines(), 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line, parse_constant=_no_constant)  # stored with allow_nan=False
                idx = rec["sample"]
                ok = rec["settings"] == self.settings_id and isinstance(idx, int) and idx >= 0
            except (ValueError, KeyError, TypeError):
                ok = False
            if not ok:
                raise CampaignError(f"{self.path}, line {no}: not a sample record of campaign "
                                    f"{self.settings_id}; the file is corrupted or from another campaign. "
                                    "Start fresh with another --out folder (or delete the folder)")
            if idx in records and records[idx] != rec:
                raise CampaignError(f"{self.path}, line {no}: a second, different record of sample {idx}; "
                                    "two campaigns wrote to this folder. Start fresh with another --out folder")
            records[idx] = rec
        return records

    def append(self, record: Mapping[str, Any]) -> None:
        """Append one record as a line, flushed and fsynced before returning.

        Parameters
        ----------
        record : mapping
            A sample record (:func:`~ilcdob.validation.campaign.run.run_sample`); standard JSON.
        """
        line = json.dumps(record, separators=(",", ":"), allow_nan=False) + "\n"
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(line)
            f.flush()
            os.fsync(f.fileno())


def _no_constant(name: str) -> None:
    raise ValueError(f"{name} in a sample record")


@contextmanager
def campaign_lock(out: Path) -> Iterator[None]:
    """Exclusive lock on ``out/samples.jsonl`` for this process (released by the OS if the process dies).

    Parameters
    ----------
    out : Path
        The campaign folder (existing).

    Raises
    ------
    CampaignError
        Another process holds the lock.
    """
    path = out / SAMPLES_FILE
    if os.path.lexists(path):  # opening a FIFO to append would wait for a reader
        check_input(path, "campaign sample store", limit=MAX_LOG_BYTES, error=CampaignError)
    f = open(path, "a")
    try:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise CampaignError(f"{out}: another campaign is running in this folder; wait for it or use "
                                "another --out folder") from None
        yield
    finally:
        f.close()


def check_settings(out: Path, settings: dict[str, Any]) -> None:
    """Write ``out/campaign_settings.json``, or check that the folder's campaign has the same settings.

    Parameters
    ----------
    out : Path
        The campaign folder (existing).
    settings : dict
        :func:`~ilcdob.validation.campaign.options.campaign_settings` of this run.

    Raises
    ------
    CampaignError
        The folder holds a campaign with other settings, an unreadable settings file, or
        samples without a settings file.
    """
    path = out / SETTINGS_FILE
    if os.path.lexists(path):
        old = read_json(path, "campaign settings file", error=CampaignError,
                        hint="start fresh with another --out folder")
        if not isinstance(old, dict):
            raise CampaignError(f"{path}: expected a JSON object, got {type(old).__name__}; start fresh with another "
                                "--out folder")
        if old.get("id") != settings["id"]:
            diff = [k for k in sorted(set(old) | set(settings)) if k not in ("id",) and old.get(k) != settings.get(k)
                    and not (k == "fleet" and isinstance(old.get(k), dict)
                             and old[k].get("sha256") == settings[k]["sha256"])]
            shown = ", ".join(f"{k}: {old.get(k)!r} there, {settings.get(k)!r} now" for k in diff) or "format"
            raise CampaignError(f"{out} holds a campaign with different settings ({shown}); refusing to mix "
                                "samples. Resume it with its settings (see its campaign_settings.json), or start "
                                "fresh with another --out folder (or delete this one)")
    else:
        if (out / SAMPLES_FILE).stat().st_size > 0:
            raise CampaignError(f"{out}: {SAMPLES_FILE} exists without {SETTINGS_FILE}, so its settings are "
                                "unknown; start fresh with another --out folder (or delete this one)")
        write_json_atomic(path, settings)
