import java.io.IOException;
import java.io.InputStream;
import java.io.Writer;
import java.nio.charset.StandardCharsets;
import java.nio.file.Files;
import java.nio.file.Path;
import java.util.ArrayList;
import java.util.Arrays;
import java.util.Comparator;
import java.util.LinkedHashMap;
import java.util.List;
import java.util.Map;
import java.util.stream.Stream;
import java.util.zip.ZipEntry;
import java.util.zip.ZipInputStream;

import javax.xml.parsers.DocumentBuilderFactory;

import org.w3c.dom.Document;
import org.w3c.dom.Element;
import org.w3c.dom.Node;
import org.w3c.dom.NodeList;

import no.ntnu.ihb.fmi4j.FmiStatus;
import no.ntnu.ihb.fmi4j.importer.fmi2.CoSimulationSlave;
import no.ntnu.ihb.fmi4j.importer.fmi2.Fmu;
import no.ntnu.ihb.fmi4j.modeldescription.variables.TypedScalarVariable;
import no.ntnu.ihb.fmi4j.modeldescription.variables.VariableType;

/**
 * Replays an SSP 1.0 archive with FMI4j (0.38) loading and running its co-simulation FMUs:
 * the SSD's components, parameter bindings (SSV), connections and the Open Simulation
 * Platform's fixed step are read here, and the FMUs are stepped by a Jacobi master.
 *
 * <pre>SspReplay SSP_PATH STOP_TIME OUT_CSV [--component NAME] [--variables v1,v2,...]</pre>
 *
 * Writes the recorded Real variables of one component at every communication point to OUT_CSV
 * and prints "STEP_US mean" (microseconds of wall time per step of the loop) on stdout; exits 1
 * when an FMI call fails or the archive holds what this harness does not play.
 *
 * FMI4j's native bridge prints the FMUs' log messages with printf on the process's stdout,
 * which Java cannot point elsewhere: the replay runs in a child JVM whose stdout is copied to
 * this process's stderr, and the child hands its STEP_US line back through a file.
 */
public final class SspReplay {
    static final String SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription";
    static final String SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues";
    static final String OSP = "http://opensimulationplatform.com/SSP/OSPAnnotations";
    static final String STEP_FILE = "sspreplay.stepfile";
    static final String USAGE = "usage: SspReplay SSP_PATH STOP_TIME OUT_CSV"
            + " [--component NAME] [--variables v1,v2,...]";

    /** An FMI call that failed, or an archive this harness cannot play. */
    static final class Failure extends Exception {
        Failure(String message) {
            super(message);
        }
    }

    /** One component of the system: its FMU and the co-simulation instance. */
    static final class Component {
        final String name;
        final Fmu fmu;
        final CoSimulationSlave slave;
        final List<Path> ssvs = new ArrayList<>();
        final Map<Long, Boolean> booleans = new LinkedHashMap<>(); // set, read back to check
        long[] outVrs = new long[0]; // the outputs connections read, in one call
        double[] outValues = new double[0];
        long[] inVrs = new long[0]; // the inputs connections write, in one call
        double[] inValues = new double[0];
        int[] inFromComponent = new int[0]; // where input j comes from: component, output index
        int[] inFromIndex = new int[0];

        Component(String name, Path fmuFile) throws IOException {
            this.name = name;
            this.fmu = Fmu.from(fmuFile.toFile());
            this.slave = fmu.asCoSimulationFmu().newInstance(name);
        }

        TypedScalarVariable<?> variable(String variable) throws Failure {
            TypedScalarVariable<?> v = slave.getModelVariables().getByNameOrNull(variable);
            if (v == null) throw new Failure(name + " has no variable " + variable);
            return v;
        }

        long real(String variable) throws Failure {
            TypedScalarVariable<?> v = variable(variable);
            if (v.getType() != VariableType.REAL) {
                throw new Failure(name + "." + variable + " is " + v.getType() + ", not Real");
            }
            return v.getValueReference();
        }

        /** Fails unless the last FMI call on this instance returned OK or Warning. */
        void check(String call) throws Failure {
            check(slave.getLastStatus(), call);
        }

        /** Fails unless the status is OK or Warning.  The FMU's own message, if it gave one,
         *  reaches stderr as FMI4j's native bridge prints it ("[FMI native bridge] status =
         *  Error, instanceName = ..."), when the child exits: after this line. */
        void check(FmiStatus s, String call) throws Failure {
            if (s != FmiStatus.OK && s != FmiStatus.Warning) {
                throw new Failure(call + " on " + name + " returned " + s);
            }
        }
    }

    public static void main(String[] args) {
        String stepFile = System.getProperty(STEP_FILE);
        int rc;
        try {
            rc = stepFile == null ? relay(args) : replay(args, Path.of(stepFile));
        } catch (Failure e) {
            System.err.println("SspReplay: " + e.getMessage());
            rc = 1;
        } catch (Exception e) {
            System.err.println("SspReplay: " + e);
            rc = 1;
        }
        System.exit(rc);
    }

    /** Runs the replay in a child JVM: its stdout (the FMUs' messages) to our stderr, its
     *  temporary files (FMI4j leaves a folder per run) in a folder removed afterwards. */
    static int relay(String[] args) throws IOException, InterruptedException {
        Path tmp = Files.createTempDirectory("sspreplay");
        Path stepFile = tmp.resolve("step");
        try {
            List<String> cmd = new ArrayList<>(List.of(
                    Path.of(System.getProperty("java.home"), "bin", "java").toString(),
                    "-Djava.io.tmpdir=" + tmp, "-D" + STEP_FILE + "=" + stepFile,
                    "-cp", System.getProperty("java.class.path"), SspReplay.class.getName()));
            cmd.addAll(Arrays.asList(args));
            Process child = new ProcessBuilder(cmd)
                    .redirectError(ProcessBuilder.Redirect.INHERIT).start();
            child.getOutputStream().close();
            try (InputStream out = child.getInputStream()) {
                out.transferTo(System.err);
            }
            System.err.flush();
            int rc = child.waitFor();
            if (rc == 0) System.out.println(Files.readString(stepFile).trim());
            return rc;
        } finally {
            deleteTree(tmp);
        }
    }

    static void deleteTree(Path dir) throws IOException {
        try (Stream<Path> paths = Files.walk(dir)) {
            paths.sorted(Comparator.reverseOrder()).forEach(p -> p.toFile().delete());
        }
    }

    static int replay(String[] argv, Path stepFile) throws Exception {
        // FMI4j logs through slf4j: slf4j-simple writes to stderr; its own notes from warn up
        System.setProperty("org.slf4j.simpleLogger.defaultLogLevel", "warn");
        System.setProperty("org.slf4j.simpleLogger.logFile", "System.err");
        List<String> positional = new ArrayList<>();
        String recordComponent = "MultirotorPlant";
        String recordVariables = "pos[1],pos[2],pos[3],euler[1],euler[2],euler[3]";
        for (int i = 0; i < argv.length; i++) {
            if (argv[i].equals("--component") || argv[i].equals("--variables")) {
                if (i + 1 == argv.length) throw new Failure(argv[i] + " needs a value; " + USAGE);
                if (argv[i].equals("--component")) recordComponent = argv[++i];
                else recordVariables = argv[++i];
            } else {
                positional.add(argv[i]);
            }
        }
        if (positional.size() != 3) throw new Failure(USAGE);
        Path ssp = Path.of(positional.get(0));
        double stopTime = Double.parseDouble(positional.get(1));
        Path outCsv = Path.of(positional.get(2));
        String[] recorded = recordVariables.split(",");

        Path dir = Files.createTempDirectory("sspreplay");
        try {
            unzip(ssp, dir);
            return run(dir, stopTime, outCsv, recordComponent, recorded, stepFile);
        } finally {
            deleteTree(dir);
        }
    }

    static int run(Path dir, double stopTime, Path outCsv, String recordComponent,
                   String[] recorded, Path stepFile) throws Exception {
        Document ssd = parse(dir.resolve("SystemStructure.ssd"));

        // the experiment: start time and the OSP fixed step
        Element experiment = first(ssd.getDocumentElement(), SSD, "DefaultExperiment");
        if (experiment == null) throw new Failure("the SSD has no DefaultExperiment");
        double start = experiment.hasAttribute("startTime")
                ? Double.parseDouble(experiment.getAttribute("startTime")) : 0.0;
        Element algorithm = first(experiment, OSP, "FixedStepAlgorithm");
        if (algorithm == null || !algorithm.hasAttribute("baseStepSize")) {
            throw new Failure("the DefaultExperiment has no osp:FixedStepAlgorithm baseStepSize");
        }
        double h = Double.parseDouble(algorithm.getAttribute("baseStepSize"));
        long n = Math.round((stopTime - start) / h);

        // the components, each with its FMU loaded by FMI4j and its parameter sets
        Map<String, Integer> index = new LinkedHashMap<>();
        List<Component> components = new ArrayList<>();
        NodeList elements = ssd.getElementsByTagNameNS(SSD, "Component");
        for (int i = 0; i < elements.getLength(); i++) {
            Element e = (Element) elements.item(i);
            Path source = inside(dir, e.getAttribute("source"));
            Component c = new Component(e.getAttribute("name"), source);
            NodeList bindings = e.getElementsByTagNameNS(SSD, "ParameterBinding");
            for (int j = 0; j < bindings.getLength(); j++) {
                Element b = (Element) bindings.item(j);
                if (!b.hasAttribute("source")) {
                    throw new Failure(c.name + ": a ParameterBinding without source");
                }
                c.ssvs.add(inside(dir, b.getAttribute("source")));
            }
            index.put(c.name, components.size());
            components.add(c);
        }

        // the connections, grouped into one read per start and one write per end component
        List<List<Long>> outs = new ArrayList<>();
        List<List<long[]>> ins = new ArrayList<>(); // {vr, from component, from output index}
        for (int i = 0; i < components.size(); i++) {
            outs.add(new ArrayList<>());
            ins.add(new ArrayList<>());
        }
        NodeList connections = ssd.getElementsByTagNameNS(SSD, "Connection");
        for (int i = 0; i < connections.getLength(); i++) {
            Element e = (Element) connections.item(i);
            Integer from = index.get(e.getAttribute("startElement"));
            Integer to = index.get(e.getAttribute("endElement"));
            if (from == null || to == null) {
                throw new Failure("connection " + e.getAttribute("startElement") + "."
                        + e.getAttribute("startConnector") + " -> " + e.getAttribute("endElement")
                        + "." + e.getAttribute("endConnector") + ": not between two components");
            }
            long outVr = components.get(from).real(e.getAttribute("startConnector"));
            long inVr = components.get(to).real(e.getAttribute("endConnector"));
            List<Long> o = outs.get(from);
            int k = o.indexOf(outVr);
            if (k < 0) {
                k = o.size();
                o.add(outVr);
            }
            ins.get(to).add(new long[] {inVr, from, k});
        }
        for (int i = 0; i < components.size(); i++) {
            Component c = components.get(i);
            c.outVrs = outs.get(i).stream().mapToLong(Long::longValue).toArray();
            c.outValues = new double[c.outVrs.length];
            List<long[]> in = ins.get(i);
            c.inVrs = in.stream().mapToLong(x -> x[0]).toArray();
            c.inValues = new double[in.size()];
            c.inFromComponent = in.stream().mapToInt(x -> (int) x[1]).toArray();
            c.inFromIndex = in.stream().mapToInt(x -> (int) x[2]).toArray();
        }

        Integer recordIndex = index.get(recordComponent);
        if (recordIndex == null) throw new Failure("no component " + recordComponent);
        Component rec = components.get(recordIndex);
        long[] recVrs = new long[recorded.length];
        for (int j = 0; j < recorded.length; j++) recVrs[j] = rec.real(recorded[j]);

        // set up, apply every parameter value, initialize (no stop time: start as stop)
        for (Component c : components) {
            c.slave.setupExperiment(start, start, 0.0);
            c.check("fmi2SetupExperiment");
            for (Path ssv : c.ssvs) applyParameters(c, ssv);
        }
        for (Component c : components) {
            c.slave.enterInitializationMode();
            c.check("fmi2EnterInitializationMode");
            for (Map.Entry<Long, Boolean> b : c.booleans.entrySet()) {
                boolean[] back = new boolean[1];
                c.check(c.slave.readBoolean(new long[] {b.getKey()}, back), "fmi2GetBoolean");
                if (back[0] != b.getValue()) {
                    throw new Failure(c.name + ": Boolean " + b.getKey() + " set to "
                            + b.getValue() + " reads back as " + back[0]);
                }
            }
        }
        for (Component c : components) {
            c.slave.exitInitializationMode();
            c.check("fmi2ExitInitializationMode");
        }

        double[][] rows = new double[(int) n + 1][recorded.length + 1];
        rows[0][0] = start;
        record(rec, recVrs, rows[0]);

        long t0 = System.nanoTime();
        for (long k = 0; k < n; k++) {
            for (Component c : components) { // (a) every connected output, all reads first
                if (c.outVrs.length == 0) continue;
                c.check(c.slave.readReal(c.outVrs, c.outValues), "fmi2GetReal");
            }
            for (Component c : components) { // (b) every connected input
                if (c.inVrs.length == 0) continue;
                for (int j = 0; j < c.inVrs.length; j++) {
                    Component from = components.get(c.inFromComponent[j]);
                    c.inValues[j] = from.outValues[c.inFromIndex[j]];
                }
                c.check(c.slave.writeReal(c.inVrs, c.inValues), "fmi2SetReal");
            }
            double t = start + k * h;
            for (Component c : components) { // (c) every component steps from t_k
                if (!c.slave.doStep(t, h)) c.check("fmi2DoStep at t = " + t); // not OK
            }
            rows[(int) k + 1][0] = start + (k + 1) * h; // (d) the values at t_{k+1}
            record(rec, recVrs, rows[(int) k + 1]);
        }
        double stepUs = n > 0 ? (System.nanoTime() - t0) / 1e3 / n : 0.0;

        for (Component c : components) {
            c.slave.terminate();
            c.check("fmi2Terminate");
            c.slave.close();
            c.fmu.close();
        }

        try (Writer w = Files.newBufferedWriter(outCsv, StandardCharsets.UTF_8)) {
            w.write("time," + String.join(",", recorded) + "\n");
            for (double[] row : rows) {
                StringBuilder line = new StringBuilder();
                for (int j = 0; j < row.length; j++) {
                    if (j > 0) line.append(',');
                    line.append(Double.toString(row[j]));
                }
                w.write(line.append('\n').toString());
            }
        }
        Files.writeString(stepFile, "STEP_US " + stepUs + "\n");
        return 0;
    }

    static void record(Component rec, long[] vrs, double[] row) throws Failure {
        double[] values = new double[vrs.length];
        rec.check(rec.slave.readReal(vrs, values), "fmi2GetReal");
        System.arraycopy(values, 0, row, 1, values.length);
    }

    /** Sets every value of an SSV parameter set on the component, by variable name. */
    static void applyParameters(Component c, Path ssv) throws Exception {
        NodeList parameters = parse(ssv).getElementsByTagNameNS(SSV, "Parameter");
        for (int i = 0; i < parameters.getLength(); i++) {
            Element p = (Element) parameters.item(i);
            String name = p.getAttribute("name");
            Element value = firstChildElement(p);
            if (value == null || !SSV.equals(value.getNamespaceURI())) {
                throw new Failure(ssv.getFileName() + ": parameter " + name + " has no value");
            }
            TypedScalarVariable<?> v = c.variable(name);
            long[] vr = {v.getValueReference()};
            String text = value.getAttribute("value");
            String kind = value.getLocalName();
            FmiStatus s;
            if (kind.equals("Real") && v.getType() == VariableType.REAL) {
                s = c.slave.writeReal(vr, new double[] {Double.parseDouble(text)});
            } else if (kind.equals("Integer") && v.getType() == VariableType.INTEGER) {
                s = c.slave.writeInteger(vr, new int[] {Integer.parseInt(text)});
            } else if (kind.equals("Boolean") && v.getType() == VariableType.BOOLEAN) {
                if (!text.equals("true") && !text.equals("false")) {
                    throw new Failure(name + ": Boolean value " + text + ", not true or false");
                }
                // FMI4j 0.38's native setBoolean passes the JVM's jboolean array (1 byte a
                // value) to fmi2SetBoolean as fmi2Boolean (4 bytes a value): value i is read
                // from bytes 4i..4i+3, the first's upper bytes from past the array.  One value
                // padded with three false bytes is read as given (checked in initialization).
                boolean b = text.equals("true");
                s = c.slave.writeBoolean(vr, new boolean[] {b, false, false, false});
                c.booleans.put(vr[0], b);
            } else {
                throw new Failure(ssv.getFileName() + ": " + name + " is " + v.getType()
                        + " in the FMU, " + kind + " in the parameter set");
            }
            c.check(s, "fmi2Set" + kind + " " + name);
        }
    }

    static Document parse(Path file) throws Exception {
        DocumentBuilderFactory f = DocumentBuilderFactory.newInstance();
        f.setNamespaceAware(true);
        return f.newDocumentBuilder().parse(file.toFile());
    }

    static Element first(Element parent, String ns, String local) {
        NodeList l = parent.getElementsByTagNameNS(ns, local);
        return l.getLength() > 0 ? (Element) l.item(0) : null;
    }

    static Element firstChildElement(Element parent) {
        for (Node n = parent.getFirstChild(); n != null; n = n.getNextSibling()) {
            if (n.getNodeType() == Node.ELEMENT_NODE) return (Element) n;
        }
        return null;
    }

    /** A path of the archive, refused when it leaves the unpacked folder. */
    static Path inside(Path dir, String relative) throws Failure {
        Path p = dir.resolve(relative).normalize();
        if (!p.startsWith(dir)) throw new Failure(relative + " points outside the archive");
        return p;
    }

    static void unzip(Path zip, Path dir) throws IOException, Failure {
        try (ZipInputStream in = new ZipInputStream(Files.newInputStream(zip))) {
            for (ZipEntry e; (e = in.getNextEntry()) != null; ) {
                Path p = inside(dir, e.getName());
                if (e.isDirectory()) {
                    Files.createDirectories(p);
                } else {
                    Files.createDirectories(p.getParent());
                    Files.copy(in, p);
                }
            }
        }
    }
}
