"""
Convert many bags: in parallel processes on this machine, or as tasks on Dask (docs/bags.md).

Each bag is a task (:func:`convert_bag`) whose failure is a :class:`BagResult`, so a bad bag
never stops the others; a task that raises (a bug, not a bad bag) is raised at the end.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import multiprocessing
import os
import signal
from typing import Any, Callable, Dict, List, Optional, Sequence, TYPE_CHECKING

from rotation_node.command_line.stop_signal import raise_if_stopped, stop_at_checkpoints
from rotation_node.errors import BagError, RotationNodeError

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters

_STORAGE_SUFFIXES = ('.zstd', '.mcap', '.db3', '.bag')
_POLL_SECONDS = 0.05   # how often the parent of the workers looks for a stop signal


@dataclasses.dataclass(frozen=True)
class BagResult:
    """What converting one bag gave: whether its output was written; a line saying what or why."""

    input_path: str
    output_path: str
    ok: bool
    line: str


def batch_output_path(input_path: str, output_directory: str) -> str:
    """
    Return the output of ``input_path`` in ``output_directory``: its name without storage suffixes.

    ``runs/day1`` -> ``OUT/day1``, ``a/imu.mcap`` -> ``OUT/imu``, ``x_0.mcap.zstd`` -> ``OUT/x_0``.
    """
    name = os.path.basename(os.path.normpath(os.fspath(input_path)))
    stripped = True
    while stripped:
        stripped = False
        for suffix in _STORAGE_SUFFIXES:
            if name.endswith(suffix) and len(name) > len(suffix):
                name, stripped = name[:-len(suffix)], True
    return os.path.join(os.fspath(output_directory), name)


def batch_output_paths(input_paths: Sequence[str], output_directory: str) -> List[str]:
    """Return :func:`batch_output_path` of every input; BagError if two are the same."""
    outputs: Dict[str, str] = {}
    for input_path in input_paths:
        output = batch_output_path(input_path, output_directory)
        if output in outputs:
            raise BagError(f'inputs {outputs[output]} and {input_path} would both be written '
                           f'to {output}; convert them into different output directories')
        outputs[output] = input_path
    return list(outputs)


def _summary(stats, params) -> str:
    """``/imu 500 -> 1000 messages (/imu/euler, /imu/quaternion)``, per converted topic."""
    from rotation_node.bag.convert import output_topic
    return '; '.join(
        f'{topic} {topic_stats.received} -> {topic_stats.published} messages '
        f'({", ".join(output_topic(topic, name) for name in params.outputs)})'
        for topic, topic_stats in stats.items())


def convert_bag(input_path: str, output_path: str, params: NodeParameters, *,
                topics: Optional[Sequence[str]] = None, overwrite: bool = False,
                strict: bool = False, compression: Optional[str] = None) -> BagResult:
    """
    Convert one bag as ``rotation_bag convert`` does; report a failure instead of raising it.

    The unit of work of :func:`convert_bags` and :func:`convert_bags_on_dask`;
    importable and picklable, so any task runner can call it.

    Parameters
    ----------
    input_path : str
        Any bag :func:`rotation_node.bag.reading.reader.open_bag` reads.
    output_path : str
        The output bag (must not exist unless ``overwrite``): a rosbag2
        directory, or a single MCAP file if it ends in ``.mcap``.
    params : rotation_node.parameters.NodeParameters
        The node's parameters, as for :func:`rotation_node.bag.convert.convert`.
    topics : list of str, optional
        As for :func:`rotation_node.bag.convert.convert`.
    overwrite, strict : bool, optional
        As for :func:`rotation_node.bag.convert.convert`.
    compression : str, optional
        As for :func:`rotation_node.bag.convert.convert` (default: the input's).

    Returns
    -------
    BagResult
        ``ok`` False, with the error line, if the bag could not be converted
        (bad or unsupported input, existing output...); nothing is written then.

    """
    from rotation_node.bag.convert import convert
    notes: List[str] = []
    try:
        with open(os.devnull, 'w') as no_progress_bar:
            stats = convert(input_path, output_path, params, topics=topics, overwrite=overwrite,
                            compression=compression, strict=strict, report=notes.append,
                            progress_stream=no_progress_bar)
    except RotationNodeError as error:
        return BagResult(os.fspath(input_path), os.fspath(output_path), False,
                         f'{input_path}: error: {_without_path(str(error), input_path)}')
    description, *notes = (_without_path(note, input_path) for note in notes)
    return BagResult(os.fspath(input_path), os.fspath(output_path), True,
                     f'{input_path} -> {output_path}: ' + '; '.join(
                         [description, _summary(stats, params), *notes]))


def _without_path(line, path):
    """``line`` on one line, without a leading ``<path>: `` (the bag's line names it)."""
    line = ' '.join(line.split())
    prefix = f'{os.fspath(path)}: '
    return line[len(prefix):] if line.startswith(prefix) else line


def convert_bags(input_paths: Sequence[str], output_directory: str, params: NodeParameters,
                 *, jobs: int = 1, topics: Optional[Sequence[str]] = None,
                 overwrite: bool = False, strict: bool = False,
                 compression: Optional[str] = None,
                 on_result: Optional[Callable[[BagResult], None]] = None) -> List[BagResult]:
    """
    Convert every input into ``output_directory``, ``jobs`` bags at a time.

    Parameters
    ----------
    input_paths : sequence of str
        The bags, any :func:`rotation_node.bag.reading.reader.open_bag` reads.
    output_directory : str
        Created if missing; outputs are named by :func:`batch_output_path`.
    params : rotation_node.parameters.NodeParameters
        The node's parameters, for every bag.
    jobs : int, optional
        Worker processes (``1``: one after the other in this process).
    topics, overwrite, strict, compression
        As for :func:`convert_bag`.
    on_result : callable, optional
        Called with each :class:`BagResult` as soon as its bag is done.

    Returns
    -------
    list of BagResult
        In the order the bags finished (those done within one poll, 50 ms,
        in input order).

    Raises
    ------
    BagError
        If ``jobs`` is not a positive integer, two inputs would share an
        output, or the output directory cannot be created (before any bag is
        converted).

    """
    if not (isinstance(jobs, int) and jobs >= 1):
        raise BagError(f'jobs must be a positive integer, got {jobs!r}')
    outputs = _created_outputs(input_paths, output_directory)
    results = _Results(on_result)
    if jobs == 1 or len(input_paths) == 1:
        for input_path, output_path in zip(input_paths, outputs):
            try:
                result = convert_bag(input_path, output_path, params, topics=topics,
                                     overwrite=overwrite, strict=strict,
                                     compression=compression)
            except Exception as error:   # noqa: B902  (re-raised once the others are done)
                results.failed(input_path, output_path, error)
            else:
                results.add(result)
        return results.all()
    # Fresh interpreters ("spawn"): forking a process that runs threads (numba's,
    # the conversion thread pool) can deadlock the child.
    context = multiprocessing.get_context('spawn')
    with concurrent.futures.ProcessPoolExecutor(max_workers=min(jobs, len(input_paths)),
                                                mp_context=context,
                                                initializer=_init_worker) as pool:
        futures = [pool.submit(_convert_bag_in_worker, input_path, output_path, params,
                               topics=topics, overwrite=overwrite, strict=strict,
                               compression=compression)
                   for input_path, output_path in zip(input_paths, outputs)]
        reported = set()
        paths = dict(zip(futures, zip(input_paths, outputs)))

        def report_completed(failed=True):
            """Report the bags done since the last call (``failed=False``: written ones only)."""
            for future in futures:
                if future not in reported and future.done() and not future.cancelled():
                    error = future.exception()
                    if error is None:
                        reported.add(future)
                        results.add(future.result())
                    elif failed:   # an error of the package or a worker, not a bad bag
                        reported.add(future)
                        results.failed(*paths[future], error)

        try:
            pending = set(futures)
            while pending:
                _, pending = concurrent.futures.wait(
                    pending, timeout=_POLL_SECONDS,
                    return_when=concurrent.futures.FIRST_COMPLETED)
                report_completed()
                raise_if_stopped()
        except BaseException:   # Ctrl-C, SIGTERM, an error: stop the workers too
            for process in list((getattr(pool, '_processes', None) or {}).values()):
                process.terminate()
            pool.shutdown(wait=True, cancel_futures=True)
            # A bag a worker completed before it saw SIGTERM is written: it gets its line.
            report_completed(failed=False)
            raise
    return results.all()


class _Results:
    """The results of a batch as they come, each passed to ``on_result``; a task's error kept."""

    def __init__(self, on_result: Optional[Callable[[BagResult], None]]) -> None:
        self._on_result = on_result or (lambda result: None)
        self._results: List[BagResult] = []
        self._error: Optional[BaseException] = None

    def add(self, result: BagResult) -> None:
        self._results.append(result)
        self._on_result(result)

    def failed(self, input_path: str, output_path: str, error: BaseException) -> None:
        self._error = self._error or error
        self.add(BagResult(os.fspath(input_path), os.fspath(output_path), False,
                           f'{input_path}: error: {type(error).__name__} in rotation_node '
                           f'(a bug, raised after the other bags): {error}'))

    def all(self) -> List[BagResult]:  # noqa: A003
        """Return every result; raise the first error of a task, if one raised."""
        if self._error is not None:
            raise self._error
        return self._results


def _init_worker():
    """
    Set a worker process's signals: Ctrl-C is the parent's, SIGTERM stops the worker.

    The parent, interrupted, terminates its workers: a conversion stops at its next check
    (its unfinished output removed), and no queued bag is started.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stop_at_checkpoints((signal.SIGTERM,))


def _convert_bag_in_worker(*args, **kwargs):
    """:func:`convert_bag` in a worker process, stoppable by SIGTERM (see ``_init_worker``)."""
    raise_if_stopped()   # a bag queued before the parent was interrupted is not started
    return convert_bag(*args, **kwargs)


def convert_bags_on_dask(client: Any, input_paths: Sequence[str], output_directory: str,
                         params: NodeParameters, *, topics: Optional[Sequence[str]] = None,
                         overwrite: bool = False, strict: bool = False,
                         compression: Optional[str] = None,
                         on_result: Optional[Callable[[BagResult], None]] = None,
                         timeout: Optional[float] = None) -> List[BagResult]:
    """
    Convert every input into ``output_directory`` as tasks on a Dask cluster.

    Each bag is one task running :func:`convert_bag` on a worker; the paths must name the same
    files on every worker (a shared file system).

    Parameters
    ----------
    client : distributed.Client
        Connected to the cluster (``Client('tcp://scheduler:8786')``, or a ``LocalCluster``).
    input_paths, output_directory, params, topics, overwrite, strict, compression, on_result
        As for :func:`convert_bags`.
    timeout : float, optional
        Seconds to wait for all tasks; ``None`` waits until they finish.

    Returns
    -------
    list of BagResult
        As :func:`convert_bags` returns them, in the order the tasks finished.

    Raises
    ------
    BagError
        If two inputs would share an output or the output directory cannot be created
        (before any task is submitted).
    TimeoutError
        If ``timeout`` passes first (the remaining tasks are cancelled).

    """
    from distributed import as_completed
    outputs = _created_outputs(input_paths, output_directory)
    # pure=False: a task is a side effect (a file written), never to be deduplicated.
    futures = client.map(convert_bag, list(input_paths), outputs, params=params, topics=topics,
                         overwrite=overwrite, strict=strict, compression=compression,
                         pure=False)
    paths = {future.key: (input_path, output_path)
             for future, input_path, output_path in zip(futures, input_paths, outputs)}
    results = _Results(on_result)
    try:
        for future in as_completed(futures, timeout=timeout):
            if future.status == 'error':   # an error of the package, not a bad bag
                results.failed(*paths[future.key], future.exception())
            else:
                results.add(future.result())
    except BaseException:
        client.cancel(futures)
        raise
    return results.all()


def _created_outputs(input_paths, output_directory):
    """Return :func:`batch_output_paths`, their directory created."""
    outputs = batch_output_paths(input_paths, output_directory)
    try:
        os.makedirs(output_directory, exist_ok=True)
    except OSError as error:
        raise BagError(f'cannot create output directory {output_directory}: '
                       f'{error.strerror}') from None
    return outputs
