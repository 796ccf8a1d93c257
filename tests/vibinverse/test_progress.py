"""The spinner: animated on a terminal, one log line elsewhere, the duration logged at the end."""

import io
import logging
import time

from vibinverse.progress import INTERVAL, spinner


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_on_a_terminal_the_message_spins_and_is_cleared(caplog):
    stream = Terminal()
    with caplog.at_level(logging.INFO, logger="vibinverse"), spinner("compiling the thing", stream=stream):
        time.sleep(3 * INTERVAL)
    text = stream.getvalue()
    assert text.count("compiling the thing") >= 2  # at least two frames drawn
    assert text.endswith("\r")  # the line is cleared for what comes next
    assert "compiling the thing: " in caplog.text and " s" in caplog.text  # the duration


def test_elsewhere_one_line_before_and_the_duration_after(caplog):
    stream = io.StringIO()  # a file or a pipe: no animation
    with caplog.at_level(logging.INFO, logger="vibinverse"), spinner("compiling", stream=stream):
        pass
    assert stream.getvalue() == ""
    assert [r.getMessage().split(":")[0] for r in caplog.records] == ["compiling ...", "compiling"]
