"""What a tab shows: scope charts, live plots, pole map and mode picker, margins,
analysis plots, filter inspector, export, action buttons, typed-value boxes and
worksheets.  A panel is built with the narrow context it needs (the GUI, callbacks,
data), never the whole tab; panels import only ``app.infra`` and the lab's modules."""
