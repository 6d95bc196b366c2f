"""
The byte layout of MCAP records that both the reader and the writer handle as arrays.

(The mcap library parses and builds every other record; these are the ones
read and written a chunk at a time with numpy.)
"""
import numpy as np

#: The first (and last) eight bytes of an MCAP file.
MCAP_MAGIC = b'\x89MCAP0\r\n'
#: The fixed part of an MCAP Message record: opcode, record length, channel id,
#: sequence, log time, publish time (31 bytes, little-endian, packed).
MESSAGE_HEADER = np.dtype([('opcode', 'u1'), ('length', '<u8'), ('channel_id', '<u2'),
                           ('sequence', '<u4'), ('log_time', '<u8'), ('publish_time', '<u8')])
#: Bytes of a Message record besides its data.
MESSAGE_RECORD_OVERHEAD = MESSAGE_HEADER.itemsize
#: What a Message record's length counts besides the data: channel id, sequence, log and
#: publish time.
MESSAGE_FIELDS = 2 + 4 + 8 + 8
