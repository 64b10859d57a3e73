"""CSV and text files: a header naming the columns, then rows of numbers (identify.data.csvfile reads them)."""
from identify.data.csvfile import read_csv
from identify.data.recording import CSV_SUFFIXES

from . import FileFormat

FORMAT = FileFormat("CSV", CSV_SUFFIXES, channels=lambda path, wanted: read_csv(path), noun="column")
