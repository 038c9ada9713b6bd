"""Files are never half-written (issue #11): every output goes to a temporary file in the
target's folder and is renamed into place only when complete; an error or an interrupt
leaves the previous file; a bad target is refused before any work, naming the option."""

import multiprocessing
import os
import stat

import pytest

from hapstab.errors import ArgumentTypeError
from hapstab.outputs import OutputError, Outputs, atomic_file, check_target, writing


def _leftovers(folder):
    return [p for p in os.listdir(folder) if p.endswith(".part")]


def test_a_complete_write_replaces_the_file(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("old\n")
    with atomic_file(p, "--csv") as fh:
        fh.write("new\n")
    assert p.read_text() == "new\n" and _leftovers(tmp_path) == []


@pytest.mark.parametrize("exc", [RuntimeError("boom"), KeyboardInterrupt()])
def test_an_error_or_interrupt_leaves_the_old_file(tmp_path, exc):
    p = tmp_path / "a.csv"
    p.write_text("old\n")
    with pytest.raises(type(exc)), atomic_file(p, "--csv") as fh:
        fh.write("half")
        raise exc
    assert p.read_text() == "old\n" and _leftovers(tmp_path) == []


def test_files_of_one_run_are_committed_together(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.png"
    a.write_text("old a")
    with pytest.raises(RuntimeError), Outputs() as out:
        with out.open(a, "--csv") as fh:
            fh.write("new a")
        with out.open(b, "--plot", "wb") as fh:
            raise RuntimeError("the plot failed")
    assert a.read_text() == "old a" and not b.exists() and _leftovers(tmp_path) == []


def test_new_files_get_the_usual_permissions(tmp_path):
    p = tmp_path / "a.csv"
    with atomic_file(p, "--csv") as fh:
        fh.write("x")
    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~mask   # not mkstemp's 0600


@pytest.mark.parametrize("path,needle", [
    ("", "--csv = '': must be a file path (it is empty)"),
    ("   ", "must be a file path"),
    ("a\0b.csv", "cannot contain a NUL character"),
])
def test_empty_targets_are_refused(path, needle):
    with pytest.raises(OutputError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        check_target(path, "--csv")


@pytest.mark.parametrize("path", [None, b"x.csv", 123, ["x.csv"]])
def test_a_target_of_the_wrong_type_is_a_type_error_naming_it(path):
    with pytest.raises(ArgumentTypeError, match=r"--csv = .*must be a file path .*got"):
        check_target(path, "--csv")
    assert issubclass(ArgumentTypeError, TypeError)


def test_to_csv_of_a_wrong_target_names_it(tmp_path):
    import hapstab as hs

    res = hs.boundary(hs.paper_hve(), [1e-3, 2e-3])
    for bad in (None, b"x.csv", 123):
        with pytest.raises(TypeError, match="must be a file path"):
            res.to_csv(bad)


def test_folders_missing_folders_and_unknown_formats_are_refused(tmp_path):
    with pytest.raises(OutputError, match="is a folder"):
        check_target(tmp_path, "--csv")
    with pytest.raises(OutputError, match=r"the folder .* does not exist"):
        check_target(tmp_path / "no" / "a.csv", "--csv")
    with pytest.raises(OutputError, match=r"--plot = .*'pgf' is not a format"):
        check_target(tmp_path / "a.pgf", "--plot", ("png", "svg"))


def test_a_device_is_written_directly_and_a_failed_write_is_an_error():
    with atomic_file("/dev/null", "--csv") as fh:
        fh.write("x")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)          # still the device
    if os.path.exists("/dev/full"):
        with pytest.raises(OutputError, match=r"--plot = '/dev/full': cannot write \(No space"), \
                atomic_file("/dev/full", "--plot", "wb") as fh:
            fh.write(b"x" * 100000)


def test_writing_passes_a_file_object_through(tmp_path):
    p = tmp_path / "a.txt"
    with p.open("w") as own, writing(own, "path") as fh:
        assert fh is own
        fh.write("direct")
    assert p.read_text() == "direct"


def _writer(args):
    path, k = args
    with atomic_file(path, "--csv") as fh:
        for i in range(20000):
            fh.write(f"{k},{i}\n")
    return k


def test_concurrent_writers_each_leave_one_complete_file(tmp_path):
    p = str(tmp_path / "c.csv")
    with multiprocessing.get_context("fork").Pool(4) as pool:
        pool.map(_writer, [(p, k) for k in range(4)])
    with open(p) as fh:
        lines = fh.read().splitlines()
    k = lines[0].split(",")[0]
    assert lines == [f"{k},{i}" for i in range(20000)]        # one writer's file, whole
    assert _leftovers(tmp_path) == []


def test_a_symbolic_link_is_written_through_and_a_files_mode_is_kept(tmp_path):
    real = tmp_path / "real.csv"
    real.write_text("old")
    os.chmod(real, 0o640)
    link = tmp_path / "link.csv"
    link.symlink_to(real)
    with atomic_file(link, "--csv") as fh:
        fh.write("new")
    assert link.is_symlink() and real.read_text() == "new"
    assert stat.S_IMODE(real.stat().st_mode) == 0o640


def test_devices_and_proc_links_are_written_in_place_never_renamed_over():
    # a review found `--csv /dev/stdout > file` renaming a temporary file over the
    # /dev/stdout link (as root): paths under /dev and /proc are always written in place
    from hapstab.outputs import _is_special

    for p in ("/dev/stdout", "/dev/null", "/proc/self/fd/1", "/dev/fd/1"):
        assert _is_special(p), p


def test_a_read_only_file_is_not_replaced(tmp_path):
    p = tmp_path / "ro.csv"
    p.write_text("keep")
    os.chmod(p, 0o444)
    if os.access(p, os.W_OK):
        pytest.skip("running with privileges that write to read-only files")
    with pytest.raises(OutputError, match="read-only"), atomic_file(p, "--csv") as fh:
        fh.write("new")
    assert p.read_text() == "keep"


def _fail_on(monkeypatch, victim):
    """os.replace in hapstab.outputs fails for one target (a rename that fails midway)."""
    import hapstab.outputs as outputs

    real = os.replace

    def replace(src, dst):
        if os.path.basename(dst) == victim:
            raise OSError(28, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(outputs.os, "replace", replace)


def test_a_commit_that_fails_midway_puts_every_previous_file_back(tmp_path, monkeypatch):
    for n in ("a", "b", "c"):
        (tmp_path / f"{n}.txt").write_text(f"old {n}")
    _fail_on(monkeypatch, "c.txt")
    with pytest.raises(OutputError, match=r"c\.txt.*No space left"), Outputs() as out:
        for n in ("a", "b", "new", "c"):
            with out.open(tmp_path / f"{n}.txt", "--out") as fh:
                fh.write(f"new {n}")
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {
        "a.txt": "old a", "b.txt": "old b", "c.txt": "old c"}   # "new.txt" removed, no .part/.old


def test_a_commit_that_succeeds_leaves_no_second_names(tmp_path):
    for n in ("a", "b"):
        (tmp_path / f"{n}.txt").write_text(f"old {n}")
    with Outputs() as out:
        for n in ("a", "b"):
            with out.open(tmp_path / f"{n}.txt", "--out") as fh:
                fh.write(f"new {n}")
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {
        "a.txt": "new a", "b.txt": "new b"}


@pytest.mark.parametrize("length", [200, 250, 255])
def test_names_up_to_the_longest_a_file_may_have_are_written(tmp_path, length):
    p = tmp_path / ("x" * (length - 4) + ".csv")
    with atomic_file(p, "--csv") as fh:
        fh.write("t\n")
    assert p.read_text() == "t\n" and [q.name for q in tmp_path.iterdir()] == [p.name]


def test_a_read_only_folder_is_refused_up_front_unless_the_file_is_writable(tmp_path, monkeypatch):
    import hapstab.outputs as outputs

    monkeypatch.setattr(outputs, "_folder_writable", lambda path: False)
    with pytest.raises(OutputError, match="is not writable"):
        check_target(tmp_path / "new.csv", "--csv")
    p = tmp_path / "old.csv"
    p.write_text("old, and longer than the new text\n")
    with atomic_file(p, "--csv") as fh:           # written in place, once complete
        fh.write("new\n")
    assert p.read_text() == "new\n" and [q.name for q in tmp_path.iterdir()] == ["old.csv"]


def test_a_file_written_in_place_is_put_back_when_a_later_rename_fails(tmp_path, monkeypatch):
    import hapstab.outputs as outputs

    ro, rw = tmp_path / "ro", tmp_path / "rw"
    ro.mkdir()
    rw.mkdir()
    (ro / "x.txt").write_text("old x, longer than the new one")
    (rw / "y.txt").write_text("old y")
    monkeypatch.setattr(outputs, "_folder_writable", lambda path: not str(path).startswith(str(ro)))
    _fail_on(monkeypatch, "y.txt")
    with pytest.raises(OutputError, match=r"y\.txt"), Outputs() as out:
        for p in (ro / "x.txt", rw / "y.txt"):
            with out.open(p, "--out") as fh:
                fh.write(f"new {p.name}")
    assert (ro / "x.txt").read_text() == "old x, longer than the new one"
    assert (rw / "y.txt").read_text() == "old y"
    assert sorted(q.name for q in rw.iterdir()) == ["y.txt"]


def test_an_interrupt_right_after_a_rename_is_undone_with_the_rest(tmp_path, monkeypatch):
    import hapstab.outputs as outputs

    for n in ("a", "b"):
        (tmp_path / f"{n}.txt").write_text(f"old {n}")
    real_put = outputs._put

    def put(tmp, target, in_place):            # the rename succeeds, then Ctrl-C lands
        real_put(tmp, target, in_place)
        if target.endswith("b.txt"):
            raise KeyboardInterrupt
    monkeypatch.setattr(outputs, "_put", put)
    with pytest.raises(KeyboardInterrupt), Outputs() as out:
        for n in ("a", "b"):
            with out.open(tmp_path / f"{n}.txt", "--out") as fh:
                fh.write(f"new {n}")
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {"a.txt": "old a",
                                                                   "b.txt": "old b"}


def test_signals_are_held_during_a_commit_and_delivered_after():
    import signal
    import time

    import hapstab.outputs as outputs

    reached = False
    with pytest.raises(KeyboardInterrupt), outputs.signals_held():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
        reached = True
    assert reached


def test_signals_are_held_while_another_thread_does_not_block_them():
    # a thread pool's thread (pyarrow's, OpenBLAS's) takes a signal sent to the process
    # when the main thread blocks it; the held block must still run to its end
    import signal
    import threading
    import time

    import hapstab.outputs as outputs

    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    reached = False
    try:
        with pytest.raises(KeyboardInterrupt), outputs.signals_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)
            reached = True
    finally:
        stop.set()
        other.join()
    assert reached


def test_a_file_without_write_permission_is_not_replaced_even_by_root(tmp_path):
    p = tmp_path / "ro.csv"
    p.write_text("old\n")
    p.chmod(0o444)
    with pytest.raises(OutputError, match="is read-only"), atomic_file(p, "--csv") as fh:
        fh.write("new\n")
    assert p.read_text() == "old\n"
