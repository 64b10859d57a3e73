"""CSV and text files: a header naming the columns, then rows of numbers (identify.csvfile reads them)."""
from identify.csvfile import read_csv
from identify.recording import CSV_SUFFIXES

from . import FileFormat

FORMAT = FileFormat("CSV", CSV_SUFFIXES, channels=lambda path, wanted: read_csv(path), noun="column")
