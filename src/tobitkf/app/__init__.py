"""The application around the library: command line, batch processing of files, HTML
report, plots, the demo job and ``tobitkf info``. Nothing in the library imports this
package. Submodules are imported on demand.
"""
