"""The learned volume's query engine: the lean sparse query (box test, decoders on the points inside, analytic
distance elsewhere), its chunking, and the CUDA-graph replays of the encode and of the static query."""
from volsmpl.volume.engine.chunks import assemble_chunks, lean_chunks, point_ranges
from volsmpl.volume.engine.encode_graph import EncodeGraphs
from volsmpl.volume.engine.lean_query import DECODER_SCOPE, LeanQuery
from volsmpl.volume.engine.query_graph import QueryGraphs, static_lean_query

__all__ = ["DECODER_SCOPE", "EncodeGraphs", "LeanQuery", "QueryGraphs", "assemble_chunks", "lean_chunks", "point_ranges",
           "static_lean_query"]
