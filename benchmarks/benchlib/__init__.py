"""What the benchmark scripts share, one concern per module (the scripts are thin wirings):

- :mod:`.paper`: the paper's numbers (Table 2, Table 3), stated once;
- :mod:`.output`: where results go by default (never into the repository unless asked);
- :mod:`.record`: the machine and load record every result JSON starts with;
- :mod:`.loop_timing`: the Track3D loop over preloaded frames with per-stage timers;
- :mod:`.torch_models`: torch eager stand-ins of the ONNX graphs (``--torch`` rows).

The runtime side (also used by `track3d bench` and the evaluation) lives in the runtime:
pinning ``track3d.machine.pin_threads``, JSON ``track3d.jsonable``, table cells
``track3d.table_text``, scores ``track3d.evaluation``.
"""
