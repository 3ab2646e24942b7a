"""A `softsync` process for the Python bench scripts: its output in a log file, a bounded
wait for a line, a clean stop."""
import os
import re
import subprocess
import time


class Proc:
    def __init__(self, binary, name, args, logdir, env=None):
        self.path = os.path.join(logdir, name + ".log")
        self.log = open(self.path, "w")
        self.p = subprocess.Popen([binary] + args, stdout=self.log, stderr=subprocess.STDOUT,
                                  env=env)

    def text(self):
        with open(self.path) as f:
            return f.read()

    def wait_for(self, pattern, within):
        end = time.time() + within
        while time.time() < end:
            m = re.search(pattern, self.text())
            if m:
                return m
            if self.p.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError(f"{self.path}: no {pattern!r} within {within}s:\n{self.text()[-2000:]}")

    def stop(self):
        """SIGTERM (a clean end: last dump, summary), SIGKILL after 20 s."""
        if self.p.poll() is None:
            self.p.terminate()
        try:
            self.p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.p.kill()
