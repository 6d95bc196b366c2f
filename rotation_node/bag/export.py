"""
The converted values of one topic of a bag as a CSV or Parquet table (``rotation_bag export``).

One row per converted sample, in log-time order: ``stamp_ns``, ``frame_id``, then the named
columns of each output (:func:`output_columns`), empty (CSV) or null (Parquet) where a sample
lacks the output. The values are ``convert``'s bit for bit (the same ``TopicConverter`` and
parameters file); CSV writes ``repr`` (the shortest text that reads back as the float64).
The input is streamed, and the table appears only once complete (``AtomicFile``).
"""
from __future__ import annotations

import csv
import io
import os
from typing import Any, Callable, List, Optional, Tuple, TYPE_CHECKING

from rotation_node import registry
from rotation_node.bag.block_convert import collections_deferred, message_blocks, TopicConverter
from rotation_node.bag.convert import check_output, input_streams
from rotation_node.bag.reading.reader import open_bag
from rotation_node.bag.writing.atomic_file import AtomicFile
from rotation_node.command_line.stop_signal import raise_if_stopped
from rotation_node.errors import BagError
from rotation_node.static_mounting import resolved_from_bag
from rotation_node.wire.stamps import header_stamp_ns

if TYPE_CHECKING:
    from rotation_node.parameters import NodeParameters
    from rotation_node.pipeline import PipelineStats
    from rotation_node.type_aliases import StrPath


def output_columns(name: str, params: NodeParameters) -> List[str]:
    """
    Return the column names of output ``name``'s numbers, in order (README, ``export``).

    Euler angles are roll, pitch, yaw for the sequence ``xyz``, else ``euler_<seq>_0..2``;
    units are the output's (radians, or degrees with ``euler.degrees``).
    """
    sequence = params.euler_sequence
    angles = (['roll', 'pitch', 'yaw'] if sequence == 'xyz'
              else [f'euler_{sequence}_{i}' for i in range(3)])
    columns = {
        'quaternion': ['qx', 'qy', 'qz', 'qw'],
        'euler': angles,
        'rotation_vector': ['rotvec_x', 'rotvec_y', 'rotvec_z'],
        'axis_angle': ['axis_x', 'axis_y', 'axis_z', 'angle'],
        'matrix': [f'r{row}{col}' for row in (1, 2, 3) for col in (1, 2, 3)],
        'angular_velocity': ['wx', 'wy', 'wz'],
        'euler_rates': [f'{angle}_rate' for angle in angles],
        'quaternion_rate': ['dqx', 'dqy', 'dqz', 'dqw'],
        'euler_stddev': [f'{angle}_stddev' for angle in angles],
        'euler_covariance': [*(f'euler_covariance_angle_{i}' for i in range(3)),
                             *(f'euler_covariance_{i}{j}' for i in range(3) for j in range(3))],
    }
    try:
        return columns[name]
    except KeyError:
        raise BagError(f'output {name} has no table columns') from None


def table_columns(params: NodeParameters) -> List[str]:
    """Return every column of the table: the leading ones, then each output's."""
    return ['stamp_ns', 'frame_id',
            *(column for name in params.outputs for column in output_columns(name, params))]


def table_format(path: StrPath) -> str:
    """Return ``'csv'`` or ``'parquet'`` from the output's extension; BagError otherwise."""
    extension = os.path.splitext(os.fspath(path))[1].lower()
    if extension not in ('.csv', '.parquet'):
        raise BagError(f'output {os.fspath(path)}: expected a .csv or .parquet file name')
    return extension[1:]


class _CsvTable:
    """Rows as CSV text into a binary stream."""

    def __init__(self, stream, columns):
        self._text = io.TextIOWrapper(stream, encoding='utf-8', newline='', write_through=True)
        self._writer = csv.writer(self._text, lineterminator='\n')
        self._writer.writerow(columns)

    def write(self, rows):
        self._writer.writerows(
            [stamp, frame_id, *('' if x is None else repr(x) for x in numbers)]
            for stamp, frame_id, numbers in rows)

    def close(self):
        self._text.flush()
        self._text.detach()


class _ParquetTable:
    """Rows as Parquet row groups (one per block) into a binary stream."""

    def __init__(self, stream, columns):
        import pyarrow as pa
        import pyarrow.parquet as pq
        self._pa = pa
        self._schema = pa.schema([pa.field('stamp_ns', pa.int64()),
                                  pa.field('frame_id', pa.string()),
                                  *(pa.field(column, pa.float64()) for column in columns[2:])])
        self._writer = pq.ParquetWriter(stream, self._schema)

    def write(self, rows):
        if not rows:
            return
        pa = self._pa
        stamps, frame_ids, numbers = zip(*rows)
        arrays = [pa.array(stamps, pa.int64()), pa.array(frame_ids, pa.string()),
                  *(pa.array(column, pa.float64()) for column in zip(*numbers))]
        self._writer.write_table(pa.Table.from_arrays(arrays, schema=self._schema))

    def close(self):
        self._writer.close()


def _parquet_available() -> None:
    try:
        import pyarrow  # noqa: F401
        import pyarrow.parquet  # noqa: F401
    except ModuleNotFoundError:
        raise BagError('writing Parquet needs pyarrow, which is not installed '
                       '(pip install pyarrow), or write a .csv file') from None
    except ImportError as error:   # installed, but not for this numpy (pyarrow >= 22: numpy 2)
        raise BagError(f'writing Parquet needs pyarrow, which does not load here ({error}); '
                       'install one that does, or write a .csv file') from None


def _rows(values_per_record, widths, positions):
    """Return the rows of records' values (``[(output, header, numbers)]``), one per header."""
    rows: List[Tuple[int, str, List[Optional[float]]]] = []
    total = sum(widths.values())
    for values in values_per_record:
        header: Any = None
        cells: List[Optional[float]] = []
        for name, sample_header, numbers in values:
            if sample_header is not header:
                if header is not None:
                    rows.append((header_stamp_ns(header), header.frame_id, cells))
                header, cells = sample_header, [None] * total
            start = positions[name]
            cells[start:start + widths[name]] = [float(x) for x in numbers]
        if header is not None:
            rows.append((header_stamp_ns(header), header.frame_id, cells))
    return rows


def export(input_path: StrPath, output_path: StrPath, params: NodeParameters, *,
           topic: Optional[str] = None, overwrite: bool = False, strict: bool = False,
           report: Optional[Callable[[str], None]] = None) -> tuple[int, PipelineStats]:
    """
    Write the converted values of one topic of a bag as a CSV or Parquet table.

    Parameters
    ----------
    input_path : str or os.PathLike
        Any bag :func:`rotation_node.bag.reading.reader.open_bag` reads; only read.
    output_path : str or os.PathLike
        ``*.csv`` or ``*.parquet``; appears only once complete.
    params : rotation_node.parameters.NodeParameters
        The node's parameters (input type, outputs, conventions).
    topic : str, optional
        The topic to export; by default the one topic of the input type
        (an error if the bag holds several).
    overwrite : bool, optional
        Replace an existing output.
    strict : bool, optional
        Refuse an unfinished recording.
    report : callable, optional
        ``report(line)`` receives what the input is and its notes.

    Returns
    -------
    rows : int
        Rows written.
    stats : PipelineStats
        The topic's conversion counters.

    Raises
    ------
    BagError
        The input cannot be read, the topic is missing, of the wrong type or
        not unique, the output's extension is not .csv or .parquet, Parquet
        without pyarrow, the output exists (without ``overwrite``) or cannot
        be written; nothing is left behind.

    """
    kind = table_format(output_path)
    if kind == 'parquet':
        _parquet_available()
    columns = table_columns(params)
    with open_bag(input_path, strict=strict) as reader:
        check_output(input_path, output_path)
        reader.report_contents(report)
        with reader.reporting_new_notes(report):
            params = resolved_from_bag(reader, params)   # the mounting from /tf_static, if asked
            streams = input_streams(reader, registry.INPUTS[params.input_type],
                                    None if topic is None else [topic])
            if len(streams) > 1:
                raise BagError(f'{reader.path} has {len(streams)} {params.input_type} topics '
                               f'({", ".join(streams)}); choose one with --topic')
            (stream, routes), = streams.items()
            converter = TopicConverter(params, {name: (name, '', None) for name in params.outputs})
            widths = {name: len(output_columns(name, params)) for name in params.outputs}
            positions, start = {}, 0
            for name in params.outputs:
                positions[name], start = start, start + widths[name]
            count = 0
            with AtomicFile(output_path, overwrite=overwrite) as output, collections_deferred():
                table = (_CsvTable if kind == 'csv' else _ParquetTable)(output.stream, columns)
                try:
                    for block in message_blocks(reader.messages(list(routes))):
                        raise_if_stopped()
                        values = converter.convert_values(
                            block, [routes[record.topic] for record in block])
                        rows = _rows(values, widths, positions)
                        table.write(rows)
                        count += len(rows)
                except BagError as error:   # a message that cannot be decoded names no file
                    raise reader.naming_this_bag(error) from None
                table.close()
                raise_if_stopped()   # the last chance before the table is committed
    return count, converter.pipeline.stats
