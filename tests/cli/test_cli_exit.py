"""What the command line does when its process ends."""

import subprocess
import sys


def test_a_run_leaves_the_final_collection_nothing_to_walk(data):
    """A command ends with every object in the collector's permanent generation
    (gc.freeze at exit, after the command closed its outputs), and only once: a hook
    registered before the run, which atexit runs after it, finds the objects frozen."""
    code = (
        "import atexit, gc\n"
        "atexit.register(lambda: print('frozen', gc.get_freeze_count() > 0))\n"
        "from lidar2city.cli.main import cli, _freeze_at_exit, _frozen_at_exit\n"
        f"cli.main(['info', {str(data / 'misc' / 'simple.laz')!r}], standalone_mode=False)\n"
        "after_run = len(_frozen_at_exit)\n"
        "cli.main(['info', '--help'], standalone_mode=False)\n"
        "_freeze_at_exit()\n"
        "print('registered', after_run, len(_frozen_at_exit), 'frozen now',"
        " gc.get_freeze_count() > 0)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-2:] == [
        "registered 1 1 frozen now False", "frozen True"]


def test_a_command_in_this_process_freezes_nothing_now(runner, data):
    """Run in a host process (tests, a notebook), a command leaves its collector as it
    was: thresholds restored, nothing frozen before the host exits."""
    import gc

    from lidar2city.cli.main import cli

    before, frozen = gc.get_threshold(), gc.get_freeze_count()
    res = runner.invoke(cli, ["info", str(data / "misc" / "simple.laz")])
    assert res.exit_code == 0, res.output
    assert gc.get_threshold() == before and gc.get_freeze_count() == frozen
