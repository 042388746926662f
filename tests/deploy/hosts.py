"""Simulated hosts of a scale-out deployment on one machine: each host is a process tree with a
host name of its own and an instance folder (DEXLABEL_VAR_DIR) that no other host can see.

Where the kernel allows it (root, or a user namespace), a host runs in private mount and UTS
namespaces: a tmpfs is mounted over the folder that holds every host's folder, so each host
sees only the folder it makes there, and gethostname() names the host. Commands run "on" a
host (``Host.run``) enter its namespaces with nsenter, as a shell on that machine would. The
test reads a host's files through ``/proc/PID/root``, the host's own view of the file system.
Without namespaces, the hosts get separate folders only (``isolated`` is False) and their
names come from DEXLABEL_HOST_NAME.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

DEXLABEL = [sys.executable, "-m", "backend.cli"]


def namespaces_available() -> bool:
    """Whether this process may make private mount and UTS namespaces (and mount a tmpfs)."""
    if not shutil.which("unshare") or not shutil.which("nsenter"):
        return False
    probe = subprocess.run(
        ["unshare", "--mount", "--uts", "--propagation", "private", "--", "sh", "-c",
         "hostname probe && mount -t tmpfs tmpfs /mnt"],
        capture_output=True, timeout=30, check=False)
    return probe.returncode == 0


class Host:
    """One host: ``name`` (its host name), ``var_dir`` (its instance folder, as it sees it)
    and ``env`` (every setting it starts with). ``start(argv)`` starts its main process; more
    commands run on it with ``run``."""

    def __init__(self, name: str, hosts_root: Path, env: dict[str, str], isolated: bool,
                 log_dir: Path) -> None:
        self.name, self.hosts_root, self.isolated = name, hosts_root, isolated
        self.var_dir = hosts_root / name / "var"
        self.env = {**env, "DEXLABEL_VAR_DIR": str(self.var_dir)}
        if not isolated:  # the machine's host name is every host's: the job table names this
            self.env["DEXLABEL_HOST_NAME"] = name
        self.log_path = log_dir / f"{name}.log"
        self.proc: subprocess.Popen[bytes] | None = None
        self.killed = False

    def start(self, *argv: str) -> None:
        """Start the host's main process (``dexlabel ARGV``), its output to ``log_path``."""
        command = [*DEXLABEL, *argv]
        if self.isolated:
            # unshare execs sh in the new namespaces (no fork), and sh execs the command, so the
            # process started here is the host's main process, inside its namespaces.
            setup = ('hostname "$0" && mount -t tmpfs -o mode=0755 tmpfs "$1" && '
                     'mkdir -p "$2" && shift 2 && exec "$@"')
            command = ["unshare", "--mount", "--uts", "--propagation", "private", "--",
                       "sh", "-c", setup, self.name, str(self.hosts_root), str(self.var_dir),
                       *command]
        else:
            self.var_dir.mkdir(parents=True)
        with self.log_path.open("ab") as log:
            self.proc = subprocess.Popen(command, env=self.env, stdout=log,
                                         stderr=subprocess.STDOUT, start_new_session=True,
                                         cwd=self.hosts_root.parent)

    @property
    def pid(self) -> int:
        assert self.proc is not None, f"{self.name} is not started"
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def run(self, *argv: str, timeout_s: float = 300,
            check: bool = True) -> subprocess.CompletedProcess[str]:
        """``dexlabel ARGV`` on this host (in its namespaces, with its settings)."""
        command = [*DEXLABEL, *argv]
        if self.isolated:
            command = ["nsenter", f"--target={self.pid}", "--mount", "--uts", "--", *command]
        done = subprocess.run(command, env=self.env, capture_output=True, text=True,
                              timeout=timeout_s, check=False, cwd=self.hosts_root.parent)
        if check:
            assert done.returncode == 0, (f"{self.name}: dexlabel {' '.join(argv)} exited "
                                          f"{done.returncode}\n{done.stdout}\n{done.stderr}")
        return done

    def path(self, inside: Path) -> Path:
        """Where this process reads ``inside`` (a path as the host sees it)."""
        if not self.isolated:
            return inside
        return Path(f"/proc/{self.pid}/root") / inside.relative_to("/")

    def files(self) -> list[str]:
        """Every file in the host's instance folder, relative to it (read while it runs)."""
        root = self.path(self.var_dir)
        return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())

    def kill(self) -> None:
        """kill -9 of the host's whole process tree, as when the machine dies."""
        self.killed = True
        if self.alive():
            os.killpg(self.pid, signal.SIGKILL)
            assert self.proc is not None
            self.proc.wait(timeout=30)

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 20 s."""
        if not self.alive():
            return
        assert self.proc is not None
        os.killpg(self.pid, signal.SIGTERM)
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.kill()

    def log_tail(self, lines: int = 40) -> str:
        text = self.log_path.read_text(errors="replace") if self.log_path.exists() else ""
        return f"--- {self.name} ---\n" + "\n".join(text.splitlines()[-lines:])
